"""The safety layer (beyond the paper, standard in ADAS): no lane change into a lane that does
not exist or into an unsafe gap, and abort a lane change whose gap closes.

A gap is safe when, in the target lane, the vehicle ahead is at least
max(min_gap, front_time_gap * v_ego) away and the ego would not reach it within min_ttc, and the
vehicle behind is at least max(min_gap, rear_time_gap * v_rear) away and would not reach the ego
within min_ttc. An abort uses the looser abort_gap / abort_ttc, so a change is not abandoned for
the margin that made it start; it counts in the target lane every vehicle whose present sideways
motion carries it there within abort_lookahead (a car cutting in from the far lane is met before
it arrives, while the ego can still turn back), and it turns back only into an origin lane the ego
can return to: nobody within abort_gap ahead in it or behind, nor behind within abort_ttc
(`turning_back_is_safer`). No change starts while a vehicle in the lane beyond
the target is within far_lane_gap of the ego, bumper to bumper: alongside, it may take the same
gap at the same moment, and a change under way cannot get out of its way (at 4 m/s an abort needs
seconds to turn back); nor, with `far_lane_leader`, while the nearest vehicle ahead in that lane
fails the gap rule for a car ahead: it may move into the target lane just in front of the ego.

No change starts either that would force the follower in the target lane to brake harder than
`follower_braking_mps2` (UN R157's lane-change criterion: 3 m/s^2, starting
`follower_reaction_s` = 0.4 s after the change starts) to stay `min_gap` behind the ego, while the
ego itself brakes as its leaders ask (the harder of what the nearest vehicles ahead in its lane and
in the target lane need to be met without contact). A change begun while braking for a stopped
car otherwise slows to a crawl between two lanes, in front of a follower that arrives at speed.

The rule is written once, as plain functions of one world's `VehicleRows` (`unsafe_vehicles`,
`lane_is_safe`, `change_blockers` and `change_is_safe` derived from it) that numba compiles:
`SafetyLayer` calls them compiled on its snapshot (its record of what blocked a change
included), the lookahead on the scene it reads, and `permitted_batch` and the batch's kernels
(`stack.batch.loop_kernels`) loop over worlds around them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable
from pydantic import BaseModel, ConfigDict, Field

from common.compiled import Kernel
from common.neighbours import (
    VehicleRows,
    lane_beyond,
    lateral_drift,
    lateral_extents,
    nearest_in_lane,
    vehicle_rows,
)
from planner.follower_forecast import unspared_follower
from records import N_ACTIONS, Command, WorldState
from records.batch import BatchColumns, WorldBatch

MAX_GAP_M = 200.0
"""Largest gap the safety layer may ask for [m]: beyond any sensor's reach on a highway."""
MAX_TIME_S = 60.0
"""Largest time gap or time to collision it may ask for [s]."""
MAX_BRAKING_MPS2 = 15.0
"""Largest braking it may grant a follower [m/s^2]: beyond any tyre's grip."""


class SafetyConfig(BaseModel):
    """Gaps in m, time gaps and TTCs in s, each bounded (`MAX_GAP_M`, `MAX_TIME_S`)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    enabled: bool = True
    min_gap_m: float = Field(6.0, ge=0, le=MAX_GAP_M, description="smallest gap to change into [m]")
    front_time_gap_s: float = Field(0.8, ge=0, le=MAX_TIME_S, description="to the car ahead [s]")
    rear_time_gap_s: float = Field(0.8, ge=0, le=MAX_TIME_S, description="for the car behind [s]")
    min_ttc_s: float = Field(4.0, ge=0, le=MAX_TIME_S, description="smallest time to collision [s]")
    abort_gap_m: float = Field(2.0, ge=0, le=MAX_GAP_M, description="gap that aborts a change [m]")
    abort_ttc_s: float = Field(1.5, ge=0, le=MAX_TIME_S, description="TTC that aborts a change [s]")
    abort_lookahead_s: float = Field(
        1.0, ge=0, le=MAX_TIME_S, description="an abort sees a car cutting in this early [s]"
    )
    far_lane_gap_m: float | None = Field(
        2.0,
        ge=0,
        le=MAX_GAP_M,
        description="no change starts while a vehicle in the lane beyond the target is this close, "
        "bumper to bumper [m] (none: no such check)",
    )
    far_lane_leader: bool = Field(
        True, description="the nearest vehicle ahead in the lane beyond the target must pass the gap rule too"
    )
    follower_braking_mps2: float | None = Field(
        3.0,
        gt=0,
        le=MAX_BRAKING_MPS2,
        description="hardest braking a change may force on the follower in the target lane [m/s^2] "
        "(none: no such check)",
    )
    follower_reaction_s: float = Field(
        0.4, ge=0, le=MAX_TIME_S, description="the follower's reaction before it brakes [s]"
    )


class SafetySettings(NamedTuple):
    """`SafetyConfig`'s numbers as compiled code takes them: gaps [m], TTCs and time gaps [s];
    `checks_far_lane` false when `far_lane_gap_m` is none (then 0), `checks_follower` false when
    `follower_braking_mps2` is none (then 0)."""

    enabled: bool
    min_gap_m: float
    min_ttc_s: float
    front_time_gap_s: float
    rear_time_gap_s: float
    abort_gap_m: float
    abort_ttc_s: float
    checks_far_lane: bool
    far_lane_gap_m: float
    far_lane_leader: bool
    checks_follower: bool
    follower_braking_mps2: float
    follower_reaction_s: float


def safety_settings(config: SafetyConfig) -> SafetySettings:
    """`config` as the compiled rule takes it."""
    far = config.far_lane_gap_m
    return SafetySettings(
        enabled=config.enabled,
        min_gap_m=config.min_gap_m,
        min_ttc_s=config.min_ttc_s,
        front_time_gap_s=config.front_time_gap_s,
        rear_time_gap_s=config.rear_time_gap_s,
        abort_gap_m=config.abort_gap_m,
        abort_ttc_s=config.abort_ttc_s,
        checks_far_lane=far is not None,
        far_lane_gap_m=0.0 if far is None else far,
        far_lane_leader=config.far_lane_leader,
        checks_follower=config.follower_braking_mps2 is not None,
        follower_braking_mps2=config.follower_braking_mps2 or 0.0,
        follower_reaction_s=config.follower_reaction_s,
    )


@register_jitable
def gap_is_clear(gap: float, min_gap: float, closing: float, min_ttc: float) -> bool:
    """The gap [m] is at least `min_gap` and the time to collision at `closing` [m/s] (infinite
    when not closing) at least `min_ttc` [s]."""
    ttc = math.inf if closing <= 0 else max(gap, 0.0) / closing
    return gap >= min_gap and ttc >= min_ttc


@register_jitable
def unsafe_vehicles(
    rows: VehicleRows,
    centre: float,
    min_gap: float,
    min_ttc: float,
    front_time_gap: float,
    rear_time_gap: float,
) -> tuple[int, int]:
    """(row ahead, row behind; -1: none) of the vehicles that make the lane centred at `centre`
    [m] unsafe for the ego: the nearest ahead and behind among one world's `rows` reaching into it
    (`common.neighbours.nearest_in_lane`), when closer than `min_gap` [m] or the time gaps [s] at
    the ego's speed (ahead) or the follower's (behind; zero: none, the loose rule) or than
    `min_ttc` [s]."""
    s, speed, length = rows.s, rows.speed, rows.length
    ahead, behind = nearest_in_lane(rows, centre)
    ego_speed = speed[0]
    unsafe_ahead, unsafe_behind = -1, -1
    if ahead >= 0:
        gap = abs(s[ahead] - s[0]) - (length[ahead] + length[0]) / 2
        if not gap_is_clear(gap, max(min_gap, front_time_gap * ego_speed), ego_speed - speed[ahead], min_ttc):
            unsafe_ahead = ahead
    if behind >= 0:
        gap = abs(s[behind] - s[0]) - (length[behind] + length[0]) / 2
        needed = max(min_gap, rear_time_gap * speed[behind])
        if not gap_is_clear(gap, needed, speed[behind] - ego_speed, min_ttc):
            unsafe_behind = behind
    return unsafe_ahead, unsafe_behind


@register_jitable
def lane_is_safe(
    rows: VehicleRows,
    centre: float,
    min_gap: float,
    min_ttc: float,
    front_time_gap: float,
    rear_time_gap: float,
) -> bool:
    """No vehicle makes the lane centred at `centre` unsafe (`unsafe_vehicles`)."""
    ahead, behind = unsafe_vehicles(rows, centre, min_gap, min_ttc, front_time_gap, rear_time_gap)
    return ahead < 0 and behind < 0


@register_jitable
def turning_back_is_safer(
    rows: VehicleRows, origin: float, target: float, min_gap: float, min_ttc: float
) -> bool:
    """Whether a lane change from the lane centred at `origin` [m] towards the one at `target` [m]
    is to be given up: the target lane is unsafe (`lane_is_safe` at the abort's `min_gap` [m] and
    `min_ttc` [s], each vehicle where its drift takes it) and the ego can return to the origin
    lane: nobody in it within `min_gap` ahead or behind, nor behind within `min_ttc`. A leader
    there that the ego closes on does not hold it in the target lane (the ego brakes for it, as it
    would have had it never left); a car alongside does: one crossing the origin lane on its way
    into the target lane (a blind driver cutting across two lanes beside the ego) makes both
    unsafe, and the ego goes on out of its way rather than turn back into it."""
    if lane_is_safe(rows, target, min_gap, min_ttc, 0.0, 0.0):
        return False
    ahead = unsafe_vehicles(rows, origin, min_gap, 0.0, 0.0, 0.0)[0]
    behind = unsafe_vehicles(rows, origin, min_gap, min_ttc, 0.0, 0.0)[1]
    return ahead < 0 and behind < 0


@register_jitable
def change_blockers(
    rows: VehicleRows, offsets: np.ndarray, lanes_count: int, lane: int, goal: int, safety: SafetySettings
) -> tuple[int, int, int, int, int, int]:
    """The rows (-1: none) that stop one world's change from `lane` to `goal`, a lane on the road
    (lanes centred at `offsets` [m]), on its `rows` where they are now: the vehicles ahead and behind
    that fail the strict gap rule in `goal`; its follower, when not spared hard braking
    (`unspared_follower`); and in the lane beyond, the vehicle ahead that fails the strict rule for a
    car ahead (with `far_lane_leader`) and those nearer than the far-lane gap bumper to bumper."""
    strict = (safety.min_gap_m, safety.min_ttc_s, safety.front_time_gap_s, safety.rear_time_gap_s)
    ahead, behind = unsafe_vehicles(rows, offsets[goal], *strict)
    follower_rule = (safety.follower_braking_mps2, safety.follower_reaction_s, safety.min_gap_m)
    follower = unspared_follower(rows, offsets, lane, goal, *follower_rule) if safety.checks_follower else -1
    far_leader, far_ahead, far_behind = -1, -1, -1
    beyond = lane_beyond(lane, goal, lanes_count)
    if safety.checks_far_lane and beyond >= 0:
        if safety.far_lane_leader:
            far_leader = unsafe_vehicles(rows, offsets[beyond], *strict)[0]
        far_ahead, far_behind = unsafe_vehicles(rows, offsets[beyond], safety.far_lane_gap_m, 0.0, 0.0, 0.0)
    return ahead, behind, follower, far_leader, far_ahead, far_behind


@register_jitable
def change_is_safe(
    rows: VehicleRows, offsets: np.ndarray, lanes_count: int, lane: int, goal: int, safety: SafetySettings
) -> bool:
    """`SafetyLayer.permits` of one world's change from `lane` to `goal`: on the road, and nothing
    blocks it (`change_blockers`)."""
    if not 0 <= goal < lanes_count:
        return False
    return max(change_blockers(rows, offsets, lanes_count, lane, goal, safety)) < 0


change_is_safe_compiled = Kernel(change_is_safe)
"""`change_is_safe` compiled, for Python callers: the per-world layer and the lookahead."""
_unsafe_vehicles = Kernel(unsafe_vehicles)
_change_blockers = Kernel(change_blockers)
_turning_back_is_safer = Kernel(turning_back_is_safer)


@dataclass(frozen=True)
class SafetyCounts:
    """What the safety layer did in an episode: commands it `masked` (replaced by STAY) and lane
    changes it `aborted`."""

    masked: int
    aborted: int


class SafetyLayer:
    """Masks unsafe commands and flags lane changes to abort; counts both. `reacted_to` holds the
    ids of the vehicles whose gap made it act last (a recording marks them)."""

    def __init__(self, config: SafetyConfig) -> None:
        self.config = config
        self.settings = safety_settings(config)
        self.masked = 0
        self.aborted = 0
        self.reacted_to: tuple[int, ...] = ()

    @property
    def counts(self) -> SafetyCounts:
        return SafetyCounts(self.masked, self.aborted)

    def permits(self, command: Command, world: WorldState, lane: int) -> bool:
        """Whether `filter` lets `command` through (without counting a mask)."""
        if command is Command.STAY or not self.config.enabled:
            return True
        return bool(
            change_is_safe_compiled(
                vehicle_rows(world),
                world.lane_offsets,
                world.lanes_count,
                lane,
                lane + command.lane_shift,
                self.settings,
            )  # fmt: skip
        )

    def filter(self, command: Command, world: WorldState, lane: int) -> Command:
        """`command`, or STAY when it leads off the road or into an unsafe gap."""
        if self.permits(command, world, lane):
            return command
        self.masked += 1
        target = lane + command.lane_shift
        self.reacted_to = self._blockers(world, lane, target) if 0 <= target < world.lanes_count else ()
        return Command.STAY

    def _blockers(self, world: WorldState, lane: int, target: int) -> tuple[int, ...]:
        """The vehicles (ids) that stop a change from `lane` into `target` (`change_blockers`)."""
        found = _change_blockers(
            vehicle_rows(world), world.lane_offsets, world.lanes_count, lane, target, self.settings
        )
        return tuple(dict.fromkeys(int(world.ids[row]) for row in found if row >= 0))

    def should_abort(self, world: WorldState, lane: int, target: int) -> bool:
        """True when a change from `lane` to `target` is to be given up (`turning_back_is_safer`):
        the gap in `target` has closed below the abort margins, counting the vehicles that move
        into it within the abort's lookahead, and `lane` has not."""
        config = self.config
        if not config.enabled:
            return False
        drift = np.concatenate(([0.0], lateral_drift(world, config.abort_lookahead_s)))
        rows = vehicle_rows(world)._replace(drift=drift)
        offsets = world.lane_offsets
        if not _turning_back_is_safer(
            rows, float(offsets[lane]), float(offsets[target]), config.abort_gap_m, config.abort_ttc_s
        ):
            return False
        self.aborted += 1
        self.reacted_to = self._unsafe(world, target, config.abort_gap_m, config.abort_ttc_s, 0.0, 0.0, rows)
        return True

    @staticmethod
    def _unsafe(
        world: WorldState,
        lane: int,
        min_gap: float,
        min_ttc: float,
        front_time_gap: float,
        rear_time_gap: float,
        rows: VehicleRows | None = None,
    ) -> tuple[int, ...]:
        """The vehicles (ids) that make `lane` unsafe (`unsafe_vehicles`) among `rows` (none: the
        world's where they are now)."""
        found = _unsafe_vehicles(
            vehicle_rows(world) if rows is None else rows, float(world.lane_offsets[lane]), min_gap, min_ttc,
            front_time_gap, rear_time_gap,
        )  # fmt: skip
        return tuple(int(world.ids[row]) for row in found if row >= 0)


def permitted_batch(
    config: SafetyConfig,
    perceived: WorldBatch,
    lane: np.ndarray,
    changing: np.ndarray,
    speed: np.ndarray,
    min_speed: float,
) -> np.ndarray:
    """(worlds, N_ACTIONS) float32, 1 where the loop would carry the command out
    (`ClosedLoop.permitted()` of every world of a batch): STAY always; a lane change when the
    maneuver of that world keeps its `lane` (not `changing`), its ego's true `speed` [m/s] is at
    least `min_speed` and the safety layer passes the gap it leads into, on what the sensor
    reports (`perceived`)."""
    reach = (perceived.lane_width + lateral_extents(perceived)) / 2
    permitted = np.zeros((perceived.worlds, N_ACTIONS), dtype=np.float32)
    _permitted(
        permitted,
        perceived.columns(),
        reach,
        np.asarray(lane, dtype=np.int64),
        np.asarray(changing, dtype=np.bool_),
        np.asarray(speed, dtype=np.float64),
        min_speed,
        safety_settings(config),
    )
    return permitted


@Kernel
def _permitted(
    out: np.ndarray,
    columns: BatchColumns,
    reach: np.ndarray,
    lane: np.ndarray,
    changing: np.ndarray,
    true_speed: np.ndarray,
    min_speed: float,
    safety: SafetySettings,
) -> None:  # pragma: no cover - compiled; covered through permitted_batch
    count, s, d, speed, length = columns.vehicles, columns.s, columns.d, columns.speed, columns.length
    lanes_count, lane_offsets = columns.lanes_count, columns.lane_offsets
    now = np.zeros(s.shape[1])
    for w in range(out.shape[0]):
        out[w, 1] = 1.0
        if changing[w] or true_speed[w] < min_speed:
            continue
        for command in (0, 2):
            target = lane[w] + command - 1
            if not safety.enabled:
                out[w, command] = 1.0
            elif change_is_safe(
                VehicleRows(count[w], s[w], d[w], speed[w], length[w], reach[w], now), lane_offsets[w],
                lanes_count[w], lane[w], target, safety,
            ):  # fmt: skip
                out[w, command] = 1.0
