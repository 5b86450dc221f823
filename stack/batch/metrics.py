"""The episode metrics of many worlds at once: `EpisodeRecorder` and `SafetyMonitor` of every world of
a batch (`stack.batch.closed_loop.ClosedLoopBatch`), fed the true worlds after every control tick
as one `WorldBatch`, to the same `Driven` and `SafetyMeasures` per world, bit for bit.

Each world's series (time, speed, heading to the lane, lateral offset, lane) fill rows of arrays,
so a tick is a few numpy writes over the batch and one compiled pass for the safety monitor's leaders
(`common.neighbours.neighbours` of every lane the ego's footprint occupies: comparisons, sums,
products and divisions; the footprint's sine and cosine as the per-world monitor takes them, on one
world's scalars). A world's episode is measured from its rows when it ends, with the per-world
functions (`lateral_comfort`, `longest_run`, `np.mean`); a collision is classified from the world's
snapshot (`classify_collision`), once per episode."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from common.compiled import Kernel
from planner.batch_safety import lateral_extents
from records.batch import WorldBatch
from stack.batch.kernels import ego_extent, reaches_lane
from stack.loop.metrics import Driven, lateral_comfort, longest_run
from stack.loop.safety_metrics import (
    _R157_GAP,
    _R157_KMH,
    R157_MIN_SPEED_MPS,
    STOPPED_SPEED_MPS,
    TTC_FLOOR_S,
    Collision,
    SafetyMeasures,
)
from stack.results.episode_result import TTC_CAP_S

SERIES = ("time", "speed", "heading", "d", "lane", "control_s")
"""What the recorder keeps of every tick, per world (`control_s`: the batch's control step, its
wall-clock time shared evenly by the worlds it ran for [s]; none at the first sample)."""


class EpisodeMetricsBatch:
    """Per world, the episode under way as `EpisodeRecorder` and `SafetyMonitor` see it: `reset`
    at a world's reset, `record` after every tick, `collided` at its first crash frame, and
    `driven(world)` / `measured(world)` when its episode ends. Ticks are `dt` seconds apart."""

    def __init__(self, worlds: int, dt: float) -> None:
        self.worlds, self.dt = worlds, dt
        self.ticks = np.zeros(worlds, dtype=np.int64)
        self.series = {name: np.zeros((worlds, 0)) for name in SERIES}
        self.was_ahead = np.zeros((worlds, 0), dtype=bool)
        self.passed = np.zeros((worlds, 0), dtype=bool)
        self.min_ttc_s = np.full(worlds, TTC_CAP_S)
        self.time_below_ttc_floor_s = np.zeros(worlds)
        self.time_below_min_distance_s = np.zeros(worlds)
        self.collision: list[Collision | None] = [None] * worlds

    def _room(self, ticks: int, vehicles: int) -> None:
        """Series rows of at least `ticks` samples and passing flags for `vehicles` rows a world."""
        held = self.series["time"].shape[1]
        if ticks > held:
            more = max(ticks - held, held)
            self.series = {name: np.pad(values, ((0, 0), (0, more))) for name, values in self.series.items()}
        more = vehicles - self.was_ahead.shape[1]
        if more > 0:
            self.was_ahead = np.pad(self.was_ahead, ((0, 0), (0, more)))
            self.passed = np.pad(self.passed, ((0, 0), (0, more)))

    def reset(self, worlds: Sequence[int], batch: WorldBatch, time: np.ndarray) -> None:
        """The worlds `worlds` begin an episode at `batch` (the truth) and `time` [s]."""
        rows = np.asarray(worlds, dtype=np.int64)
        self.ticks[rows] = 0
        self.passed[rows] = False
        self.was_ahead[rows] = False
        self.min_ttc_s[rows] = TTC_CAP_S
        self.time_below_ttc_floor_s[rows] = 0.0
        self.time_below_min_distance_s[rows] = 0.0
        for world in rows.tolist():
            self.collision[world] = None
        flags = np.zeros(self.worlds, dtype=bool)
        flags[rows] = True
        self._record_world(flags, batch, time, 0.0)

    def record(
        self, stepped: np.ndarray, batch: WorldBatch, time: np.ndarray, crashed: np.ndarray, control_s: float
    ) -> list[int]:
        """One tick of the worlds flagged `stepped`, at `batch` (the truth) and `time` [s], whose
        control step took `control_s` seconds of wall-clock time for them all; the worlds whose ego
        `crashed` on it for the first time: classify each (`collided`)."""
        self._record_world(stepped, batch, time, control_s / max(int(stepped.sum()), 1))
        reach = (batch.lane_width + lateral_extents(batch)) / 2
        ego_lane_gap = np.full(self.worlds, np.nan)
        below_floor = np.zeros(self.worlds, dtype=bool)
        _monitor(
            stepped, batch.columns(), batch.heading, batch.lane_heading, reach, batch.lane_width,
            TTC_FLOOR_S, self.min_ttc_s, below_floor, ego_lane_gap,
        )  # fmt: skip
        self.time_below_ttc_floor_s[stepped] += self.dt * below_floor[stepped]
        speed = batch.speed[:, 0]
        minimum = np.where(
            speed < R157_MIN_SPEED_MPS, 0.0, speed * np.interp(speed * 3.6, _R157_KMH, _R157_GAP)
        )
        below_distance = stepped & (ego_lane_gap < minimum)
        self.time_below_min_distance_s[below_distance] += self.dt
        return [w for w in np.flatnonzero(stepped & crashed).tolist() if self.collision[w] is None]

    def collided(self, world: int, collision: Collision) -> None:
        """World `world`'s ego collided: `collision` (`classify_collision` of its crash frame)."""
        self.collision[world] = collision

    def _record_world(self, flags: np.ndarray, batch: WorldBatch, time: np.ndarray, control_s: float) -> None:
        """The worlds flagged in `flags`, one sample more: the recorder's series and passed cars."""
        self._room(int(self.ticks.max(initial=0)) + 1, batch.s.shape[1])
        rows = np.flatnonzero(flags)
        at = self.ticks[rows]
        values = {
            "time": time,
            "speed": batch.speed[:, 0],
            "heading": batch.heading[:, 0] - batch.lane_heading,
            "d": batch.d[:, 0],
            "lane": batch.lane[:, 0],
            "control_s": np.full(self.worlds, control_s),
        }
        for name, value in values.items():
            self.series[name][rows, at] = value[rows]
        self.ticks[rows] += 1
        vehicles = batch.s.shape[1]
        others = np.arange(vehicles)[None, :]
        present = (others >= 1) & (others < batch.count[:, None])
        ahead = (batch.s > batch.s[:, :1]) & present
        was_ahead = self.was_ahead[:, :vehicles]
        passing = flags[:, None] & was_ahead & ~ahead & present
        self.passed[:, :vehicles] |= passing
        self.was_ahead[:, :vehicles] = np.where(flags[:, None], ahead, was_ahead)

    def _samples(self, world: int, name: str) -> np.ndarray:
        return self.series[name][world, : self.ticks[world]]

    def driven(self, world: int) -> Driven:
        """`EpisodeRecorder.driven` of world `world`'s episode so far."""
        time, speed = self._samples(world, "time"), self._samples(world, "speed")
        lane = self._samples(world, "lane")
        peak_accel, peak_jerk = lateral_comfort(self._samples(world, "heading"), speed, self.dt)
        return Driven(
            steps=len(time) - 1,
            duration_s=float(time[-1] - time[0]),
            passed_cars=int(np.count_nonzero(self.passed[world])),
            mean_speed=float(np.mean(speed)),
            peak_lat_accel=peak_accel,
            peak_lat_jerk=peak_jerk,
            longest_standstill_s=longest_run(speed[1:] < STOPPED_SPEED_MPS) * self.dt,
            time_in_leftmost_lane_s=float(np.count_nonzero(lane[1:] == 0) * self.dt),
            trace={
                "time": time.tolist(),
                "speed": speed.tolist(),
                "d": self._samples(world, "d").tolist(),
            },
        )

    def control_ms(self, world: int) -> tuple[float, float]:
        """(p50, p95) of world `world`'s share of the control step per tick [ms] this episode, as
        `ClosedLoop.solve_statistics` reports the controller's time per tick."""
        shares = 1e3 * self._samples(world, "control_s")[1:]
        if not shares.size:
            return 0.0, 0.0
        p50, p95 = np.percentile(shares, [50, 95])
        return float(p50), float(p95)

    def measured(self, world: int, departed: bool) -> SafetyMeasures:
        """`SafetyMonitor.measured` of world `world`'s episode so far, which `departed` the road or
        not (`ClosedLoopBatch.departed`)."""
        collision = self.collision[world]
        return SafetyMeasures(
            road_departure=departed,
            at_fault_collision=collision is not None and collision.at_fault,
            collision_kind=collision.kind if collision is not None else "",
            min_ttc_s=float(self.min_ttc_s[world]),
            time_below_min_distance_s=float(self.time_below_min_distance_s[world]),
            time_below_ttc_floor_s=float(self.time_below_ttc_floor_s[world]),
        )


@Kernel
def _monitor(
    stepped: np.ndarray,
    columns: tuple[np.ndarray, ...],
    heading: np.ndarray,
    lane_heading: np.ndarray,
    reach: np.ndarray,
    lane_width: float,
    ttc_floor: float,
    min_ttc: np.ndarray,
    below_floor: np.ndarray,
    ego_lane_gap: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`SafetyMonitor.record` in each `stepped` world but the collision, the road departure (the
    loop's `settle` flags it) and the R157 distance: the leader in every lane the ego's footprint
    occupies (`reach` (W, V): how far each vehicle reaches across from its centre [m]) with the
    smallest TTC kept in `min_ttc` and whether one is below `ttc_floor` [s] in `below_floor`, and
    the gap to the leader in the ego's own lane (NaN: none) in `ego_lane_gap`."""
    count, s, d, speed, length, width, lane, lanes_count, offsets = columns
    for w in range(stepped.shape[0]):
        if not stepped[w]:
            continue
        low, high = ego_extent(w, d, length, width, heading, lane_heading)
        v, n, ego_lane = speed[w, 0], count[w], lane[w, 0]
        for j in range(lanes_count[w]):
            occupied = reaches_lane(low, high, offsets[w, j], lane_width)
            if not occupied and j != ego_lane:
                continue
            leader, nearest = -1, math.inf
            for k in range(1, n):
                rel = s[w, k] - s[w, 0]
                if rel > 0 and abs(d[w, k] - offsets[w, j]) < reach[w, k] and (leader < 0 or rel < nearest):
                    leader, nearest = k, rel
            if leader < 0:
                continue
            gap = abs(s[w, leader] - s[w, 0]) - (length[w, leader] + length[w, 0]) / 2
            if j == ego_lane:
                ego_lane_gap[w] = gap
            if occupied and gap > 0 and v > speed[w, leader]:
                ttc = gap / (v - speed[w, leader])
                min_ttc[w] = min(min_ttc[w], ttc)
                if ttc < ttc_floor:
                    below_floor[w] = True
