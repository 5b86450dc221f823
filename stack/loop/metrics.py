"""The episode's recorders, and the tracking metrics of a lane change, with the definitions of
docs/architecture.md.

- passed car: a vehicle counts once, the first time it goes from ahead of the ego to behind it;
- accuracy: passed / (passed + collided) x 100 over all episodes.

`EpisodeRecorder` records one world's episode; `EpisodeMetricsBatch` records those of many worlds at
once as rows of arrays. Both hand their samples (`EpisodeSamples`) to the measurers the episode
record's fields declare (`stack.results.episode_measures.measured`), and the surroundings to the
safety monitor's `leaders_ahead`: one measure, one function, for one world and many.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba.extending import register_jitable

from common.compiled import Kernel
from common.neighbours import lateral_extents
from records import Lane, WorldState
from records.batch import WorldBatch
from stack.fault.preventability import Fault
from stack.fault.truth_ring import TruthRing
from stack.loop.loop_records import Tick
from stack.loop.safety_metrics import (
    Collision,
    SafetyMeasures,
    leaders_ahead_batch,
    monitor_measures,
    r157_min_following_distances,
    restart,
)
from stack.results.episode_measures import EpisodeSamples, lateral_comfort
from stack.sim.batch.arrays import BatchArrays


@dataclass(frozen=True)
class Tracking:
    """How one lane change tracked its reference (lengths in m, accelerations in m/s^2, jerk in
    m/s^3): duration from the start of lateral motion (|d - d0| > 1 cm) to staying within 0.1 m of
    the target centre (None if it never settles), overshoot past that centre, RMS and max error."""

    duration_s: float | None
    overshoot_m: float
    rms_error_m: float
    max_error_m: float
    peak_lat_accel: float
    peak_lat_jerk: float


def tracking(
    time: np.ndarray,
    d: np.ndarray,
    d_reference: np.ndarray,
    heading: np.ndarray,
    speed: np.ndarray,
    dt: float,
) -> Tracking:
    """Tracking metrics of a lane change from `d[0]` to `d_reference[-1]`, sampled every tick."""
    d_origin, d_target = d[0], d_reference[-1]
    moving = np.flatnonzero(np.abs(d - d_origin) > 0.01)
    outside = np.flatnonzero(np.abs(d - d_target) > 0.1)
    duration_s = None
    if moving.size and (not outside.size or outside[-1] < len(d) - 1):
        end = outside[-1] + 1 if outside.size else 0
        duration_s = float(time[end] - time[moving[0]])
    peak_accel, peak_jerk = lateral_comfort(heading, speed, dt)
    error = d - d_reference
    return Tracking(
        duration_s=duration_s,
        overshoot_m=float(max(0.0, np.max(np.sign(d_target - d_origin) * (d - d_target)))),
        rms_error_m=float(np.sqrt(np.mean(error**2))),
        max_error_m=float(np.max(np.abs(error))),
        peak_lat_accel=peak_accel,
        peak_lat_jerk=peak_jerk,
    )


@dataclass(frozen=True, eq=False)
class Traces:
    """What the recorder recorded, as arrays (copies): the ego's `time` [s], lateral offset `d`
    [m], `heading` relative to the road's first lane at its position [rad] and `speed` [m/s] at
    the start and after every control tick (one sample more than ticks), and the reference's
    `d_reference` [m] and the commanded `steering` [rad] of every tick."""

    time: np.ndarray
    d: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    d_reference: np.ndarray
    steering: np.ndarray


class EpisodeRecorder:
    """Collects what the metrics need: the world after every control tick (and at the start),
    and the reference and actuation of every tick."""

    def __init__(self, world: WorldState) -> None:
        self.was_ahead = np.zeros(0, dtype=bool)
        self.passed = np.zeros(0, dtype=bool)
        self.time: list[float] = []
        self.speed: list[float] = []
        self.heading: list[float] = []
        self.d: list[float] = []
        self.lane: list[int] = []
        self.d_reference: list[float] = []
        self.steering: list[float] = []
        self._record_world(world)

    def __deepcopy__(self, memo: dict[int, Any]) -> EpisodeRecorder:
        """A copy that records on independently: its containers hold numbers only, so copying the
        containers is a deep copy (without visiting every number; the oracle copies the loop at
        every branch)."""
        copied = copy.copy(self)
        copied.__dict__.update({name: copy.copy(value) for name, value in self.__dict__.items()})
        memo[id(self)] = copied
        return copied

    def record(self, tick: Tick) -> None:
        """One tick: what it tracked, what it commanded, and the world it led to."""
        self.d_reference.append(tick.reference.d)
        self.steering.append(tick.actuation.steering)
        self._record_world(tick.world)

    @property
    def passed_cars(self) -> int:
        """The vehicles passed so far (`passing`)."""
        return int(np.count_nonzero(self.passed))

    def _record_world(self, world: WorldState) -> None:
        more = int(world.ids.max()) + 1 - len(self.passed)
        if more > 0:
            self.was_ahead, self.passed = (
                np.pad(flags, (0, more)) for flags in (self.was_ahead, self.passed)
            )
        _passing(world.s, world.ids, self.was_ahead, self.passed)
        self.time.append(world.time)
        self.speed.append(float(world.speed[0]))
        self.heading.append(float(world.heading[0]) - world.lanes[0].heading_at(float(world.s[0])))
        self.d.append(float(world.d[0]))
        self.lane.append(world.ego_lane)

    def traces(self) -> Traces:
        """Everything recorded so far, as arrays (see `Traces`)."""
        return Traces(
            time=np.array(self.time),
            d=np.array(self.d),
            heading=np.array(self.heading),
            speed=np.array(self.speed),
            d_reference=np.array(self.d_reference),
            steering=np.array(self.steering),
        )

    def samples(self, dt: float) -> EpisodeSamples:
        """What was recorded, as the measurers take it (ticks `dt` seconds apart)."""
        recorded = (self.time, self.speed, self.heading, self.d, self.lane)
        time, speed, heading, d, lane = (np.array(values) for values in recorded)
        return EpisodeSamples(time, speed, heading, d, lane, self.passed_cars, dt)


@register_jitable
def passing(s: np.ndarray, kept: np.ndarray, was_ahead: np.ndarray, passed: np.ndarray) -> None:
    """One sample of the passed-car rule in one world, whose vehicles stand at `s` [m] along the
    road (row 0 the ego), each kept as `kept[row]` in the flags `was_ahead` and `passed`: another
    vehicle counts as passed (once: a flag) the first time it goes from ahead of the ego to behind
    it; one not seen before was not ahead."""
    for row in range(1, len(kept)):
        ahead = s[row] > s[0]
        if was_ahead[kept[row]] and not ahead:
            passed[kept[row]] = True
        was_ahead[kept[row]] = ahead


_passing = Kernel(passing)


@Kernel
def passing_batch(
    flags: np.ndarray, s: np.ndarray, count: np.ndarray, was_ahead: np.ndarray, passed: np.ndarray
) -> None:  # pragma: no cover - compiled
    """`passing` in each world flagged in `flags`, its vehicles the first `count` rows of `s` and of
    its flags; the rows beyond hold no vehicle, so none of them is ahead."""
    for w in range(flags.shape[0]):
        if flags[w]:
            passing(s[w], np.arange(count[w]), was_ahead[w], passed[w])
            was_ahead[w, count[w] : s.shape[1]] = False


SERIES = ("time", "speed", "heading", "d", "lane", "control_s")
"""What the recorder keeps of every tick, per world (`control_s`: the batch's control step, its
wall-clock time shared evenly by the worlds it ran for [s]; none at the first sample)."""


class EpisodeMetricsBatch:
    """Per world, the episode under way as `EpisodeRecorder` and `SafetyMonitor` see it: `reset`
    at a world's reset, `record` after every tick, `collided` at its first crash frame, and
    `samples(world)` / `measured(world)` when its episode ends. Ticks are `dt` seconds apart."""

    def __init__(self, worlds: int, dt: float) -> None:
        self.worlds, self.dt = worlds, dt
        self.truth = TruthRing(worlds, dt)
        self.ticks = np.zeros(worlds, dtype=np.int64)
        self.series = {name: np.zeros((worlds, 0)) for name in SERIES}
        self.was_ahead = np.zeros((worlds, 0), dtype=bool)
        self.passed = np.zeros((worlds, 0), dtype=bool)
        self.kept = monitor_measures(worlds)
        self.collision: list[Collision | None] = [None] * worlds
        self.fault: list[Fault | None] = [None] * worlds

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

    def reset(self, worlds: Sequence[int], batch: WorldBatch, arrays: BatchArrays, time: np.ndarray) -> None:
        """The worlds `worlds` begin an episode at `batch` (the truth; the traffic's `arrays`) and
        `time` [s]."""
        rows = np.asarray(worlds, dtype=np.int64)
        self.ticks[rows] = 0
        self.passed[rows] = False
        self.was_ahead[rows] = False
        restart(self.kept, rows)
        for world in rows.tolist():
            self.collision[world] = self.fault[world] = None
        flags = np.zeros(self.worlds, dtype=bool)
        flags[rows] = True
        self._record_world(flags, batch, time, 0.0)
        self.truth.reset(worlds, batch, arrays, time)

    def record(
        self,
        stepped: np.ndarray,
        batch: WorldBatch,
        arrays: BatchArrays,
        time: np.ndarray,
        crashed: np.ndarray,
        control_s: float,
    ) -> list[int]:
        """One tick of the worlds flagged `stepped`, at `batch` (the truth; the traffic's `arrays`)
        and `time` [s], whose control step took `control_s` seconds of wall-clock time for them
        all; the worlds whose ego `crashed` on it for the first time: classify each (`collided`)."""
        self._record_world(stepped, batch, time, control_s / max(int(stepped.sum()), 1))
        self.truth.record(stepped, batch, arrays, time)
        reach = (batch.lane_width + lateral_extents(batch)) / 2
        leaders_ahead_batch(
            stepped, batch.columns(), batch.heading, batch.lane_heading, reach, batch.lane_width,
            r157_min_following_distances(batch.speed[:, 0]), self.kept, self.dt,
        )  # fmt: skip
        return [w for w in np.flatnonzero(stepped & crashed).tolist() if self.collision[w] is None]

    def collided(self, world: int, collision: Collision, lanes: tuple[Lane, ...]) -> None:
        """World `world`'s ego collided: `collision` (`classify_collision` of its crash frame on the
        road of `lanes`), judged as one world judges it over the truth kept (`TruthRing.judged`;
        not judged where none is)."""
        self.collision[world] = collision
        self.fault[world] = self.truth.judged(world, collision.kind, collision.other, lanes)

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
        passing_batch(flags, batch.s, batch.count, self.was_ahead, self.passed)

    def _samples(self, world: int, name: str) -> np.ndarray:
        return self.series[name][world, : self.ticks[world]]

    def samples(self, world: int) -> EpisodeSamples:
        """`EpisodeRecorder.samples` of world `world`'s episode so far."""
        time, speed, heading, d = (self._samples(world, name) for name in ("time", "speed", "heading", "d"))
        passed = int(np.count_nonzero(self.passed[world]))
        return EpisodeSamples(time, speed, heading, d, self._samples(world, "lane"), passed, self.dt)

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
        not (`ClosedLoopBatch.departed`), its collision's fault as judged (by the contact's geometry
        alone where it was not: `stack.runs.batch_episodes` judges it then)."""
        return SafetyMeasures.of(departed, self.collision[world], self.fault[world])
