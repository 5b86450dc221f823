"""Why the ego braked at emergency strength: each activation of `controllers.emergency` is
attributed to one cause, from the simulator's truth about the vehicle it braked for and the ego's
own maneuver over the last `RECENT_S` seconds, checked in this order:

- `phantom`: the vehicle braked for does not exist in the truth (a false positive of the sensor);
- `cut_in`: it left the wandering zone of its lane (R157's 0.375 m: a lane change of its own
  under way, in or out), or was moving sideways fast enough to leave it within `LEAVING_SOON_S`
  (the cruise takes a car cutting in as a leader that early), within `RECENT_S`;
- `leader_braking`: it slowed at about 3 m/s^2 or harder (`HARD_BRAKING_MPS2`) on some tick
  within `RECENT_S`;
- `own_lane_change`: the ego's lane change was under way within `RECENT_S` (aborted ones too);
- `closing_in`: none of those (the ego drove up to a slower vehicle).

The per-tick law is written once (`vehicle_events`, `observe_rows`, `emergency_cause`):
`CauseTracker` calls it on one world, a memory column per vehicle id, `CausesBatch` (for
`stack.batch.closed_loop_batch.ClosedLoopBatch`) on the rows of a batch."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba.extending import register_jitable

from common.compiled import Kernel
from common.neighbours import WANDERING_M
from records import WorldState
from records.batch import BatchColumns, WorldBatch

TRACK_MATCH_ALONG_M = 3.0
"""A tracked vehicle is a real one when a true vehicle's centre is this close along the road [m]
(the length of `drivestack tracking`'s 3 m gate; across the road the match keeps to the lane)."""
TRACK_MATCH_ACROSS_M = 1.5
"""... and this close across it [m]."""


def true_row(s: float, d: float, truth_s: np.ndarray, truth_d: np.ndarray) -> int:
    """The row (from 1: row 0 is the ego) of the true vehicle whose centre is nearest a tracked
    vehicle's at (`s`, `d`) [m] within `TRACK_MATCH_ALONG_M` x `TRACK_MATCH_ACROSS_M`, or -1: a track
    braked for is a phantom only when no true vehicle lies under it (its id is the tracker's own)."""
    along, across = np.abs(truth_s[1:] - s), np.abs(truth_d[1:] - d)
    near = (along < TRACK_MATCH_ALONG_M) & (across < TRACK_MATCH_ACROSS_M)
    if not near.any():
        return -1
    return 1 + int(np.argmin(np.where(near, along, np.inf)))


def tracked_true_rows(
    braking: np.ndarray, slot: np.ndarray, slots: np.ndarray, perceived: WorldBatch, truth: WorldBatch
) -> np.ndarray:
    """Per world, the `slot` emergency braking braked for, or, in the worlds flagged `braking` (a
    new emergency braking in a tracked world: `slots` map each perceived row to its slot), the true
    row under the track braked for (`true_row`), -1 for none."""
    rows = slot.copy()
    for world in np.flatnonzero(braking).tolist():
        found = np.flatnonzero(slots[world, 1:] == slot[world])
        rows[world] = -1
        if len(found):
            row, count = 1 + int(found[0]), int(truth.count[world])
            rows[world] = true_row(
                float(perceived.s[world, row]), float(perceived.d[world, row]),
                truth.s[world, :count], truth.d[world, :count],
            )  # fmt: skip
    return rows


CAUSES = ("cut_in", "leader_braking", "own_lane_change", "closing_in", "phantom")
"""The causes, in the order of the counts (`EpisodeResult.emergency_brakings_<cause>`)."""
CUT_IN, LEADER_BRAKING, OWN_LANE_CHANGE, CLOSING_IN, PHANTOM = range(len(CAUSES))
RECENT_S = 2.0
"""How far back a vehicle's lane change or hard braking, or the ego's lane change, causes an
activation [s]."""
LEAVING_SOON_S = 1.0
"""A vehicle whose sideways speed carries it out of its wandering zone within this time is
leaving it already [s]: `controller.cut_in_lookahead_s`'s default."""
HARD_BRAKING_MPS2 = 2.9
"""A vehicle slowing harder than this on a tick brakes hard [m/s^2]: 3 m/s^2 or more, with slack
for a tick's rounding."""
NEVER = -math.inf
"""The time of an event that has not happened [s]."""
CLOCK_TOLERANCE_S = 1e-6
"""Slack on the window (`RECENT_S`): an event exactly that far back counts on every clock's
rounding [s]."""


@dataclass(frozen=True)
class BrakingsByCause:
    """An episode's emergency brakings per cause: its fields are `EpisodeResult`'s of the same names."""

    emergency_brakings_cut_in: int
    emergency_brakings_leader_braking: int
    emergency_brakings_own_lane_change: int
    emergency_brakings_closing_in: int
    emergency_brakings_phantom: int

    @classmethod
    def of(cls, counts: Sequence[int]) -> BrakingsByCause:
        """From the counts in the order of `CAUSES`."""
        return cls(*(int(count) for count in counts))


def cause_label(cause: int) -> str:
    """`CAUSES[cause]` as a report writes it ("cut-in", "leader braking", ...)."""
    return CAUSES[cause].replace("_", " ").replace("cut in", "cut-in")


@register_jitable
def vehicle_events(
    drift: float, slowing: float, time: float, drifted_at: float, braked_at: float
) -> tuple[float, float]:
    """One tick of one vehicle seen at `time` [s], `drift` [m] from its lane's centre and slowing
    at `slowing` [m/s^2]: the last time it was outside the wandering zone and the last time it
    braked hard [s], from those before (`drifted_at`, `braked_at`)."""
    if drift > WANDERING_M:
        drifted_at = time
    if slowing > HARD_BRAKING_MPS2:
        braked_at = time
    return drifted_at, braked_at


@register_jitable
def emergency_cause(
    phantom: bool, time: float, drifted_at: float, braked_at: float, ego_changed_at: float, recent_s: float
) -> int:
    """The cause (an index of `CAUSES`) of an activation at `time` [s] for a vehicle that is a
    `phantom`, or was last outside its wandering zone at `drifted_at` and last braked hard at
    `braked_at`, the ego's lane change last under way at `ego_changed_at` [s], each counting
    within `recent_s` [s] (`RECENT_S` for emergency braking)."""
    recent = recent_s + CLOCK_TOLERANCE_S
    if phantom:
        return PHANTOM
    if time - drifted_at <= recent:
        return CUT_IN
    if time - braked_at <= recent:
        return LEADER_BRAKING
    if time - ego_changed_at <= recent:
        return OWN_LANE_CHANGE
    return CLOSING_IN


@register_jitable
def observe_rows(
    time: float,
    count: int,
    d: np.ndarray,
    speed: np.ndarray,
    heading_to_lane: np.ndarray,
    lane: np.ndarray,
    offsets: np.ndarray,
    columns: np.ndarray,
    dt: float,
    seen: np.ndarray,
    speed_before: np.ndarray,
    drifted_at: np.ndarray,
    braked_at: np.ndarray,
) -> None:
    """`vehicle_events` of the vehicles in rows 1 to `count` - 1 of one world's truth at `time` [s]
    (lateral offset `d` [m], `speed` [m/s], `lane` of lanes centred at `offsets` [m]), row r's memory
    in column `columns[r]`: `seen` 1 where the vehicle was in the last frame, its speed then in
    `speed_before` [m/s], `drifted_at` and `braked_at` [s]. Its drift is the farther of where it is
    and where its sideways speed (speed times the sine of `heading_to_lane` [rad]) takes it in
    `LEAVING_SOON_S`, as the cruise's leaders see a car cutting in (`controllers.leaders`)."""
    for row in range(1, count):
        column = columns[row]
        slowing = (speed_before[column] - speed[row]) / dt if seen[column] else 0.0
        sideways = speed[row] * math.sin(heading_to_lane[row])
        off = d[row] - offsets[lane[row]]
        drift = max(abs(off), abs(off + sideways * LEAVING_SOON_S))
        drifted_at[column], braked_at[column] = vehicle_events(
            drift, slowing, time, drifted_at[column], braked_at[column]
        )
        speed_before[column] = speed[row]
    seen[:] = 0
    for row in range(1, count):
        seen[columns[row]] = 1


_observe_rows = Kernel(observe_rows)


class CauseTracker:
    """One world's memory for `emergency_cause`, a column per vehicle id (`observe_rows`); the last
    time the ego changed lane; the counts per cause. `observe` every frame of the truth (the first
    included), `ego` and `attribute` on a control tick."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.columns: dict[int, int] = {}
        self.seen = np.zeros(0, dtype=np.int64)
        self.speed_before = np.zeros(0)
        self.drifted_at = np.zeros(0)
        self.braked_at = np.zeros(0)
        self.ego_changed_at = NEVER
        self.counts = [0] * len(CAUSES)
        self.last: int | None = None
        """The cause of the latest activation (None before the first)."""

    def _column(self, vehicle: int) -> int:
        column = self.columns.setdefault(vehicle, len(self.columns))
        if column >= self.seen.size:
            more = max(self.seen.size, 16)
            self.seen = np.pad(self.seen, (0, more))
            self.speed_before = np.pad(self.speed_before, (0, more))
            self.drifted_at = np.pad(self.drifted_at, (0, more), constant_values=NEVER)
            self.braked_at = np.pad(self.braked_at, (0, more), constant_values=NEVER)
        return column

    def observe(self, world: WorldState) -> None:
        """The truth `world` after a frame (or at the start)."""
        columns = np.array([self._column(vehicle) for vehicle in world.ids.tolist()], dtype=np.int64)
        _observe_rows(
            world.time, world.count, world.d, world.speed,
            world.heading - world.lanes[0].heading_at(float(world.s[0])), world.lane, world.lane_offsets,
            columns, self.dt, self.seen, self.speed_before, self.drifted_at, self.braked_at,
        )  # fmt: skip

    def ego(self, time: float, changing_lane: bool) -> None:
        """The ego's maneuver on the control tick at `time` [s]: a lane change runs or not."""
        if changing_lane:
            self.ego_changed_at = time

    def attribute(self, world: WorldState, vehicle: int | None, perceived: WorldState | None = None) -> int:
        """Count an activation on the control tick at the truth `world` for `vehicle` (an id of what
        the sensor reported, or of a track in `perceived`, matched to the truth by `true_row`): its
        cause."""
        ids = world.ids.tolist()
        if vehicle is not None and vehicle not in ids and perceived is not None and vehicle in perceived.ids:
            row = perceived.ids.tolist().index(vehicle)
            match = true_row(float(perceived.s[row]), float(perceived.d[row]), world.s, world.d)
            vehicle = ids[match] if match > 0 else None
        phantom = vehicle is None or vehicle not in ids
        column = self.columns.get(-1 if vehicle is None else vehicle)
        cause = emergency_cause(
            phantom,
            world.time,
            NEVER if column is None else float(self.drifted_at[column]),
            NEVER if column is None else float(self.braked_at[column]),
            self.ego_changed_at,
            RECENT_S,
        )
        self.counts[cause] += 1
        self.last = cause
        return cause


@Kernel
def observe_batch(
    stepped: np.ndarray,
    time: np.ndarray,
    columns: BatchColumns,
    heading_to_lane: np.ndarray,
    dt: float,
    seen: np.ndarray,
    speed_before: np.ndarray,
    drifted_at: np.ndarray,
    braked_at: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`observe_rows` in each `stepped` world of a batch, a memory column per row (a vehicle):
    `seen`, `speed_before` [m/s], `drifted_at` and `braked_at` [s] (W, rows); each vehicle's
    `heading_to_lane` [rad] (W, rows)."""
    rows = np.arange(seen.shape[1])
    for w in range(stepped.shape[0]):
        if stepped[w]:
            observe_rows(
                time[w], columns.vehicles[w], columns.d[w], columns.speed[w], heading_to_lane[w],
                columns.lane[w], columns.lane_offsets[w], rows, dt, seen[w], speed_before[w], drifted_at[w],
                braked_at[w],
            )  # fmt: skip


class CausesBatch:
    """`stack.fault.emergency_causes.CauseTracker` of each world of a batch, one row a world and a
    column a truth row (a vehicle): `seen`, `speed_before` [m/s], `drifted_at`, `braked_at` [s];
    the last time the ego changed lane [s] and the counts per cause (W, causes)."""

    def __init__(self, worlds: int) -> None:
        self.seen = np.zeros((worlds, 0), dtype=np.int64)
        self.speed_before = np.zeros((worlds, 0))
        self.drifted_at = np.full((worlds, 0), NEVER)
        self.braked_at = np.full((worlds, 0), NEVER)
        self.ego_changed_at = np.full(worlds, NEVER)
        self.counts = np.zeros((worlds, len(CAUSES)), dtype=np.int64)

    def _room(self, vehicles: int) -> None:
        more = vehicles - self.seen.shape[1]
        if more > 0:
            self.seen = np.pad(self.seen, ((0, 0), (0, more)))
            self.speed_before = np.pad(self.speed_before, ((0, 0), (0, more)))
            self.drifted_at = np.pad(self.drifted_at, ((0, 0), (0, more)), constant_values=NEVER)
            self.braked_at = np.pad(self.braked_at, ((0, 0), (0, more)), constant_values=NEVER)

    def reset(self, worlds: np.ndarray, batch: WorldBatch, time: np.ndarray, dt: float) -> None:
        """The worlds flagged in `worlds` begin an episode at the truth `batch`."""
        self._room(batch.s.shape[1])
        self.seen[worlds] = 0
        self.drifted_at[worlds] = self.braked_at[worlds] = NEVER
        self.ego_changed_at[worlds] = NEVER
        self.counts[worlds] = 0
        self.observe(worlds, batch, time, dt)

    def observe(self, stepped: np.ndarray, batch: WorldBatch, time: np.ndarray, dt: float) -> None:
        """The truth `batch` after a frame of the worlds flagged `stepped`."""
        self._room(batch.s.shape[1])
        observe_batch(
            stepped, time, batch.columns(), batch.heading - batch.lane_heading[:, None], dt, self.seen,
            self.speed_before, self.drifted_at, self.braked_at,
        )  # fmt: skip

    def attribute(
        self,
        live: np.ndarray,
        changing: np.ndarray,
        time: np.ndarray,
        flags: np.ndarray,
        activations: np.ndarray,
        vehicle_room: int,
        tracked_rows: np.ndarray | None = None,
    ) -> None:
        """A control tick of the worlds flagged `live` at `time` [s], their ego `changing` lane, with
        emergency braking's `flags` ([active, activations, slot]) after it and its `activations`
        before it: count each new activation by its cause (a slot from `vehicle_room` on is a
        phantom's; `tracked_rows`, when the worlds are tracked: per world, the true row of the track
        braked for, -1 for none)."""
        self.ego_changed_at = np.where(live & changing, time, self.ego_changed_at)
        for world in np.flatnonzero(live & (flags[:, 1] > activations)).tolist():
            slot = int(flags[world, 2]) if tracked_rows is None else int(tracked_rows[world])
            phantom = slot >= vehicle_room or slot < 0
            row = 0 if phantom else slot
            cause = emergency_cause(
                phantom,
                float(time[world]),
                float(self.drifted_at[world, row]),
                float(self.braked_at[world, row]),
                float(self.ego_changed_at[world]),
                RECENT_S,
            )
            self.counts[world, cause] += 1
