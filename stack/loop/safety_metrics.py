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
  moved into it).
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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.neighbours import footprint_lateral_extent, neighbours, occupied_lanes
from common.r157 import R157_GAP as _R157_GAP  # noqa: F401  (the batched metrics read R157's table here)
from common.r157 import R157_KMH as _R157_KMH  # noqa: F401
from common.r157 import R157_MIN_SPEED_MPS, R157_TIME_GAP, r157_min_following_distance  # noqa: F401
from records import WorldState
from stack.results.episode_result import TTC_CAP_S

DEPARTURE_TOLERANCE_M = 0.3
"""How far a footprint corner may lie beyond the road edge before it counts as a departure [m]."""
STOPPED_SPEED_MPS = 0.5
"""Below this speed a vehicle counts as stopped [m/s]."""
TTC_FLOOR_S = 1.5
"""Time to collision below which a tick counts towards the time below the TTC floor [s]."""

AT_FAULT_KINDS = ("front", "stopped vehicle", "lane change", "off road")
NOT_AT_FAULT_KINDS = ("ego stopped", "rear", "side swipe")


def road_edges(world: WorldState) -> tuple[float, float]:
    """(lowest, highest) lateral coordinate [m] of the drivable area: the outer edges of the outer lanes."""
    half, offsets = world.lane_width / 2, world.lane_offsets.tolist()
    return min(offsets) - half, max(offsets) + half


def departed(world: WorldState) -> bool:
    """A footprint corner lies more than DEPARTURE_TOLERANCE_M beyond the road edges."""
    return _departed(world, footprint_lateral_extent(world))


def _departed(world: WorldState, extent: tuple[float, float]) -> bool:
    low, high = extent
    edge_low, edge_high = road_edges(world)
    return bool(low < edge_low - DEPARTURE_TOLERANCE_M or high > edge_high + DEPARTURE_TOLERANCE_M)


@dataclass(frozen=True)
class Collision:
    """What the ego hit and who is at fault (see the module docstring for `kind`)."""

    kind: str

    @property
    def at_fault(self) -> bool:
        return self.kind in AT_FAULT_KINDS


def classify_collision(world: WorldState, changing_lane: bool) -> Collision:
    """The category of the ego's collision in `world` (the first frame its `crashed` flag is set);
    `changing_lane`: the maneuver is in a lane change."""
    if departed(world):
        return Collision("off road")
    other = _collided_with(world)
    if world.speed[0] < STOPPED_SPEED_MPS:
        return Collision("ego stopped")
    if other is None:
        return Collision("front")
    heading = float(world.heading[0])
    delta = world.position[other] - world.position[0]
    along = float(delta[0] * math.cos(heading) + delta[1] * math.sin(heading))
    across = float(-delta[0] * math.sin(heading) + delta[1] * math.cos(heading))
    in_two_lanes = len(occupied_lanes(world)) > 1
    if abs(along) - world.length[0] / 2 >= abs(across) - world.width[0] / 2:
        if along > 0:
            return Collision("stopped vehicle" if world.speed[other] < STOPPED_SPEED_MPS else "front")
        return Collision("lane change" if changing_lane or in_two_lanes else "rear")
    return Collision("lane change" if changing_lane or in_two_lanes else "side swipe")


def _collided_with(world: WorldState) -> int | None:
    """Row of the crashed vehicle whose centre is closest to the ego's (None if none is flagged)."""
    crashed = np.flatnonzero(world.crashed[1:]) + 1
    if not crashed.size:
        return None
    distance = np.linalg.norm(world.position[crashed] - world.position[0], axis=1)
    return int(crashed[np.argmin(distance)])


@dataclass(frozen=True)
class SafetyMeasures:
    """What the safety monitor measured of an episode (module docstring; times in s): its fields
    are `EpisodeResult`'s of the same names."""

    road_departure: bool
    at_fault_collision: bool
    collision_kind: str
    min_ttc_s: float
    time_below_min_distance_s: float
    time_below_ttc_floor_s: float


class SafetyMonitor:
    """Per-episode safety record, fed the true world after every control tick."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.min_ttc_s = TTC_CAP_S
        self.time_below_min_distance_s = 0.0
        self.time_below_ttc_floor_s = 0.0
        self.road_departure = False
        self.collision: Collision | None = None

    def record_departure(self, world: WorldState) -> None:
        """Only whether the ego left the road in `world` (what ends an episode early)."""
        self.road_departure = self.road_departure or departed(world)

    def record(self, world: WorldState, changing_lane: bool) -> None:
        if world.crashed[0] and self.collision is None:
            self.collision = classify_collision(world, changing_lane)
        extent = footprint_lateral_extent(world)
        self.road_departure = self.road_departure or _departed(world, extent)
        v = float(world.speed[0])
        below_floor = False
        for lane in occupied_lanes(world, extent):
            leader = neighbours(world, lane)[0]
            if leader is not None and leader.gap > 0 and v > leader.speed:
                ttc = leader.gap / (v - leader.speed)
                self.min_ttc_s = min(self.min_ttc_s, ttc)
                below_floor = below_floor or ttc < TTC_FLOOR_S
        self.time_below_ttc_floor_s += self.dt * below_floor
        leader = neighbours(world, world.ego_lane)[0] if 0 <= world.ego_lane < world.lanes_count else None
        if leader is not None and leader.gap < r157_min_following_distance(v):
            self.time_below_min_distance_s += self.dt

    def measured(self) -> SafetyMeasures:
        """The episode so far (see `SafetyMeasures`)."""
        collision = self.collision
        return SafetyMeasures(
            road_departure=self.road_departure,
            at_fault_collision=collision is not None and collision.at_fault,
            collision_kind=collision.kind if collision is not None else "",
            min_ttc_s=self.min_ttc_s,
            time_below_min_distance_s=self.time_below_min_distance_s,
            time_below_ttc_floor_s=self.time_below_ttc_floor_s,
        )
