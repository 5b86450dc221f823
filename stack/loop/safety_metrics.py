"""Closed-loop safety metrics, as planners are judged by nuPlan and lane keeping systems by UN R157.

- **road departure**: a corner of the ego's footprint lies more than `DEPARTURE_TOLERANCE_M` beyond
  the road's outer lane edges (nuPlan's drivable-area compliance, whose violation threshold is
  0.3 m); it ends the episode as a failure, like highway-env's `offroad_terminal`.
- **collision fault** (nuPlan's collision categories): the contact side is the side of the ego's
  footprint the other's centre lies beyond, in the ego's body frame (front or rear when it is
  further beyond the bumper than beyond the flank, else a side). At fault: the ego hits something
  with its front (`front`), hits a stopped vehicle (`stopped vehicle`), touches a vehicle side on
  while its footprint spans two lanes or it is changing lane (`lane change`), or collides while off
  the road (`off road`). Not at fault: the ego stands (`ego stopped`), is hit from behind while
  keeping one lane (`rear`), or is touched side on while keeping one lane (`side swipe`: the other
  moved into it). That is the contact's geometry; who is at fault is decided as R157 decides
  preventability (`stack.fault.preventability`): the ego's own lane change and leaving the road stay at
  fault, any other contact is at fault when R157's careful and competent driver, replayed in the
  ego's place over the last seconds, avoids it (`fault_reason` says why).
- **minimum time to collision** [s]: gap / closing speed to the nearest vehicle ahead in each lane
  the ego's footprint occupies, over the episode (`TTC_CAP_S` when nothing ever closed in); a
  vehicle alongside (its centre ahead, its rear beside the ego: gap <= 0) is not ahead of the ego's
  path, and a contact with it is a side collision, counted as such.
- **time below the R157 minimum following distance** [s]: the gap to the vehicle ahead in the ego's
  lane is below d_min = v * t_front(v), UN R157 paragraph 5.2.3.3's table (1.0 s at 7.2 km/h up
  to 1.6 s at 60 km/h, linear in between, 1.6 s above); counted from 7.2 km/h up.
- **time below the TTC floor** [s]: the TTC (as for the minimum) to a vehicle ahead in a lane the
  ego occupies is below `TTC_FLOOR_S` (nuPlan's TTC metric, whose floor is 0.95 s; the benchmark's
  share of time above a floor).

The per-tick laws are plain functions of one world's rows, which numba compiles: the leaders' TTC
and gap (`leaders_ahead`) and what the monitor adds up of them (`watch`, into `MonitorMeasures`).
`SafetyMonitor` calls them on its world, and `leaders_ahead_batch` loops over the worlds of a batch
(`stack.loop.metrics.EpisodeMetricsBatch`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numba.extending import register_jitable

from common.compiled import Kernel
from common.neighbours import (
    VehicleRows,
    footprint_across,
    footprint_lateral_extent,
    nearest_in_lane,
    occupied_lanes,
    reaches_lane,
    vehicle_rows,
)
from common.r157 import (  # noqa: F401  (R157's distance, read here by the loop and the batch)
    R157_MIN_SPEED_MPS,
    R157_TIME_GAP,
    r157_min_following_distance,
    r157_min_following_distances,
)
from records import WorldState
from records.batch import BatchColumns
from stack.fault.preventability import Fault, WorldHistory, judge
from stack.results.episode_measures import STOPPED_SPEED_MPS
from stack.results.episode_result import TTC_CAP_S

DEPARTURE_TOLERANCE_M = 0.3
"""How far a footprint corner may lie beyond the road edge before it counts as a departure [m]."""
TTC_FLOOR_S = 1.5
"""Time to collision below which a tick counts towards the time below the TTC floor [s]."""

AT_FAULT_KINDS = ("front", "stopped vehicle", "lane change", "off road")
NOT_AT_FAULT_KINDS = ("ego stopped", "rear", "side swipe")


def departed(world: WorldState) -> bool:
    """A footprint corner lies more than DEPARTURE_TOLERANCE_M beyond the road edges."""
    return _departed(world, footprint_lateral_extent(world))


def _departed(world: WorldState, extent: tuple[float, float]) -> bool:
    return bool(departs(*extent, world.lane_offsets, world.lanes_count, world.lane_width))


@register_jitable
def departs(low: float, high: float, offsets: np.ndarray, lanes_count: int, lane_width: float) -> bool:
    """A footprint spanning [`low`, `high`] across the road [m] lies more than
    `DEPARTURE_TOLERANCE_M` beyond the outer edges of the `lanes_count` lanes centred at `offsets`
    [m], each `lane_width` [m] wide (the road departure of one world, for one world or many)."""
    lowest, highest = offsets[0], offsets[0]
    for lane in range(1, lanes_count):
        if offsets[lane] < lowest:
            lowest = offsets[lane]
        if offsets[lane] > highest:
            highest = offsets[lane]
    edge_low, edge_high = lowest - lane_width / 2, highest + lane_width / 2
    return low < edge_low - DEPARTURE_TOLERANCE_M or high > edge_high + DEPARTURE_TOLERANCE_M


@dataclass(frozen=True)
class Collision:
    """What the ego hit (see the module docstring for `kind`) and the id of the vehicle it touched
    (None: none is flagged); `at_fault` is the contact geometry's verdict alone."""

    kind: str
    other: int | None = None

    @property
    def at_fault(self) -> bool:
        return self.kind in AT_FAULT_KINDS


def classify_collision(world: WorldState, changing_lane: bool) -> Collision:
    """The category of the ego's collision in `world` (the first frame its `crashed` flag is set);
    `changing_lane`: the maneuver is in a lane change."""
    if departed(world):
        return Collision("off road")
    other = _collided_with(world)
    if other is None:
        return Collision("ego stopped" if world.speed[0] < STOPPED_SPEED_MPS else "front")
    vehicle = int(world.ids[other])
    if world.speed[0] < STOPPED_SPEED_MPS:
        return Collision("ego stopped", vehicle)
    heading = float(world.heading[0])
    delta = world.position[other] - world.position[0]
    along = float(delta[0] * math.cos(heading) + delta[1] * math.sin(heading))
    across = float(-delta[0] * math.sin(heading) + delta[1] * math.cos(heading))
    in_two_lanes = len(occupied_lanes(world)) > 1
    if abs(along) - world.length[0] / 2 >= abs(across) - world.width[0] / 2:
        if along > 0:
            return Collision(
                "stopped vehicle" if world.speed[other] < STOPPED_SPEED_MPS else "front", vehicle
            )
        return Collision("lane change" if changing_lane or in_two_lanes else "rear", vehicle)
    return Collision("lane change" if changing_lane or in_two_lanes else "side swipe", vehicle)


def _collided_with(world: WorldState) -> int | None:
    """Row of the crashed vehicle whose centre is closest to the ego's (None if none is flagged)."""
    crashed = np.flatnonzero(world.crashed[1:]) + 1
    if not crashed.size:
        return None
    distance = np.linalg.norm(world.position[crashed] - world.position[0], axis=1)
    return int(crashed[np.argmin(distance)])


@dataclass(frozen=True)
class SafetyMeasures:
    """How the safety monitor judged an episode (module docstring): its fields are
    `EpisodeResult`'s of the same names."""

    road_departure: bool
    at_fault_collision: bool
    collision_kind: str
    fault_reason: str

    @classmethod
    def of(cls, road_departure: bool, collision: Collision | None, fault: Fault | None) -> SafetyMeasures:
        """The measures of an episode that ended in `collision` (none: it did not collide), judged
        `fault` (none: by its geometry alone, the reason left empty)."""
        if fault is None and collision is not None:
            fault = Fault(collision.at_fault, "")
        return cls(
            road_departure=road_departure,
            at_fault_collision=fault is not None and fault.at_fault,
            collision_kind=collision.kind if collision is not None else "",
            fault_reason=fault.reason if fault is not None else "",
        )


class MonitorMeasures(NamedTuple):
    """What the safety monitor adds up over an episode's ticks (module docstring; times in s), one
    value a world (row `w` of each array): each starts at its `MONITOR_START` value and changes in
    `watch` only; its fields are `EpisodeResult`'s of the same names."""

    min_ttc_s: np.ndarray
    time_below_min_distance_s: np.ndarray
    time_below_ttc_floor_s: np.ndarray


MONITOR_START = (TTC_CAP_S, 0.0, 0.0)
"""Each of `MonitorMeasures`' values before an episode's first tick."""


def monitor_measures(worlds: int) -> MonitorMeasures:
    """`MonitorMeasures` of `worlds` worlds, each at its start."""
    return MonitorMeasures(*(np.full(worlds, start) for start in MONITOR_START))


def restart(kept: MonitorMeasures, worlds: np.ndarray) -> None:
    """The rows `worlds` of `kept` back at their start (an episode begins there)."""
    for values, start in zip(kept, MONITOR_START, strict=True):
        values[worlds] = start


def monitored(kept: MonitorMeasures, world: int) -> dict[str, Any]:
    """World `world`'s `MonitorMeasures` by name."""
    return {name: float(values[world]) for name, values in zip(MonitorMeasures._fields, kept, strict=True)}


@register_jitable
def watch(
    kept: MonitorMeasures, w: int, ttc: float, ego_lane_gap: float, min_distance: float, dt: float
) -> None:
    """One tick of `dt` [s] in world `w` of `kept` (`MonitorMeasures`), its leaders as
    `leaders_ahead` found them: the smallest TTC [s] and the gap [m] to the leader in the ego's
    lane (NaN: none), against R157's minimum following distance at the ego's speed [m]."""
    kept.min_ttc_s[w] = min(kept.min_ttc_s[w], ttc)
    if ttc < TTC_FLOOR_S:
        kept.time_below_ttc_floor_s[w] += dt
    if ego_lane_gap < min_distance:
        kept.time_below_min_distance_s[w] += dt


class SafetyMonitor:
    """Per-episode safety record, fed the true world after every control tick (and, for the
    replay that judges a collision's fault, at the start: `start`)."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.history = WorldHistory(dt)
        self.fault: Fault | None = None
        self.kept = monitor_measures(1)
        self.road_departure = False
        self.collision: Collision | None = None

    @property
    def min_ttc_s(self) -> float:
        return float(self.kept.min_ttc_s[0])

    @property
    def time_below_min_distance_s(self) -> float:
        return float(self.kept.time_below_min_distance_s[0])

    def record_departure(self, world: WorldState) -> None:
        """Only whether the ego left the road in `world` (what ends an episode early)."""
        self.road_departure = self.road_departure or departed(world)

    def start(self, world: WorldState) -> None:
        """The episode's first frame."""
        self.history.add(world)

    def record(self, world: WorldState, changing_lane: bool) -> None:
        self.history.add(world)
        if world.crashed[0] and self.collision is None:
            self.collision = classify_collision(world, changing_lane)
            self.fault = judge(self.collision.kind, self.collision.other, self.history.worlds, self.dt)
        extent = footprint_lateral_extent(world)
        self.road_departure = self.road_departure or _departed(world, extent)
        ttc, ego_lane_gap = _leaders_ahead(
            vehicle_rows(world),
            world.lane_offsets,
            world.lanes_count,
            world.ego_lane,
            *extent,
            world.lane_width,
        )
        seen = not math.isnan(ego_lane_gap)
        min_distance = r157_min_following_distance(float(world.speed[0])) if seen else 0.0
        watch(self.kept, 0, ttc, ego_lane_gap, min_distance, self.dt)

    def measured(self) -> SafetyMeasures:
        """How the episode so far is judged (its sums: `kept`, `monitored`)."""
        return SafetyMeasures.of(self.road_departure, self.collision, self.fault)


@register_jitable
def leaders_ahead(
    rows: VehicleRows,
    offsets: np.ndarray,
    lanes_count: int,
    ego_lane: int,
    low: float,
    high: float,
    lane_width: float,
) -> tuple[float, float]:
    """One tick of the monitor's leaders in one world (`rows` where they are now): the smallest
    TTC [s] to the leader (`common.neighbours.nearest_in_lane`) of a lane (centred at `offsets`
    [m]) that the ego's footprint [`low`, `high`] [m] reaches into, when a gap is open and closing
    (inf: none), and the gap [m] to the leader of its lane `ego_lane` (NaN: none)."""
    s, speed, length = rows.s, rows.speed, rows.length
    ego_speed = speed[0]
    smallest, ego_lane_gap = math.inf, math.nan
    for lane in range(lanes_count):
        occupied = reaches_lane(low, high, offsets[lane], lane_width)
        if not occupied and lane != ego_lane:
            continue
        leader = nearest_in_lane(rows, offsets[lane])[0]
        if leader < 0:
            continue
        gap = abs(s[leader] - s[0]) - (length[leader] + length[0]) / 2
        if lane == ego_lane:
            ego_lane_gap = gap
        if occupied and gap > 0 and ego_speed > speed[leader]:
            smallest = min(smallest, gap / (ego_speed - speed[leader]))
    return smallest, ego_lane_gap


_leaders_ahead = Kernel(leaders_ahead)


@Kernel
def leaders_ahead_batch(
    stepped: np.ndarray,
    columns: BatchColumns,
    heading: np.ndarray,
    lane_heading: np.ndarray,
    reach: np.ndarray,
    lane_width: float,
    min_distance: np.ndarray,
    kept: MonitorMeasures,
    dt: float,
) -> None:  # pragma: no cover - compiled
    """`leaders_ahead` and `watch` in each `stepped` world of a batch (`reach` (W, V); R157's
    `min_distance` [m] at each ego's speed), as `SafetyMonitor.record` takes them, into `kept`."""
    count, s, d, speed, length, width = (
        columns.vehicles,
        columns.s,
        columns.d,
        columns.speed,
        columns.length,
        columns.width,
    )
    lane, lanes_count, offsets = columns.lane, columns.lanes_count, columns.lane_offsets
    now = np.zeros(s.shape[1])
    for w in range(stepped.shape[0]):
        if not stepped[w]:
            continue
        low, high = footprint_across(d[w, 0], length[w, 0], width[w, 0], heading[w, 0] - lane_heading[w])
        rows = VehicleRows(count[w], s[w], d[w], speed[w], length[w], reach[w], now)
        ttc, ego_lane_gap = leaders_ahead(rows, offsets[w], lanes_count[w], lane[w, 0], low, high, lane_width)
        watch(kept, w, ttc, ego_lane_gap, min_distance[w], dt)
