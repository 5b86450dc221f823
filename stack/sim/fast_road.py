"""The `fast` simulation backend: highway-env's own road, with its two all-pairs hot spots indexed.

Profiled on highway-v0 defaults (50 vehicles), stock highway-env spends ~50 % of a frame in
`Road.neighbour_vehicles` (every IDM/MOBIL vehicle, several times a frame, projects every other
vehicle onto a lane) and ~25 % in the pairwise collision loop. `FastRoad` keeps highway-env's
vehicles, behaviours and physics untouched and changes only how those two are computed:

- neighbour queries: while `Road.act()` runs, positions cannot change, so each lane's projection
  of every vehicle (s, lateral, on-lane) is computed once per frame and shared by all queries;
- collisions: a numpy broad phase over all pairs keeps only pairs within highway-env's own
  spherical pre-check distance (plus a small margin); the stock `handle_collisions` then runs on
  those pairs, in the stock order, so impacts and crash flags are the same.

Both pick exactly what stock picks (the same vehicle objects, the same tie-breaking), so
trajectories are identical; `tests/test_fast_road.py` checks it frame by frame.
"""

from __future__ import annotations

from bisect import bisect_left
from functools import cached_property

import numpy as np
from highway_env.envs.highway_env import HighwayEnvFast
from highway_env.road.lane import AbstractLane, StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.utils import wrap_to_pi
from highway_env.vehicle.objects import Landmark, RoadObject

from stack.sim.traffic import ExitTraffic, ScenarioTraffic

BROAD_PHASE_MARGIN = 1e-6
"""Extra distance [m] the broad phase admits, so float rounding never drops a stock candidate."""
NEIGHBOUR_MARGIN = 1.0
"""Lateral margin [m] of highway-env's `on_lane` test in `neighbour_vehicles`."""

LaneIndex = tuple[str, str, int]
"""highway-env's lane index: (from node, to node, lane id)."""


_SUBCLASS: dict[tuple[type, type], bool] = {}


def is_kind(cls: type, base: type) -> bool:
    """`issubclass(cls, base)`, remembered: `isinstance` by an object's type, for every object of
    every frame."""
    known = _SUBCLASS.get((cls, base))
    if known is None:
        known = _SUBCLASS[cls, base] = issubclass(cls, base)
    return known


class LaneProjections:
    """Per-frame cache: every road object projected on each queried lane."""

    def __init__(self, road: Road, vehicle_position: np.ndarray | None = None) -> None:
        """`vehicle_position`, when given, is where the road's vehicles stand (n x 2) [m], known
        already; the other objects' positions are read."""
        self.road = road
        candidates = road.vehicles + road.objects
        landmarks = {cls for cls in set(map(type, candidates)) if is_kind(cls, Landmark)}
        self.objects = [o for o in candidates if type(o) not in landmarks] if landmarks else candidates
        self.vehicles_first = not landmarks
        """Whether the road's vehicles are the first rows, in road order (no landmark left out)."""
        if vehicle_position is None or not self.vehicles_first:
            self.position = np.array([o.position for o in self.objects], dtype=float).reshape(-1, 2)
        else:
            others = [o.position for o in self.objects[len(vehicle_position) :]]
            self.position = np.concatenate([vehicle_position, np.array(others, dtype=float).reshape(-1, 2)])
        self.lanes: dict[LaneIndex, tuple[list[float], list[int]]] = {}

    @cached_property
    def row(self) -> dict[int, int]:
        """Each object's row, by its id."""
        return {id(o): i for i, o in enumerate(self.objects)}

    def sorted_on_lane(self, lane_index: LaneIndex) -> tuple[list[float], list[int]]:
        """The objects highway-env counts as on `lane_index`'s lane, sorted by (s, row): their s
        [m] and their rows."""
        cached = self.lanes.get(lane_index)
        if cached is None:
            s, on = self._project(self.road.network.get_lane(lane_index))
            rows = np.flatnonzero(on)
            order = rows[np.lexsort((rows, s[rows]))]
            cached = self.lanes[lane_index] = (s[order].tolist(), order.tolist())
        return cached

    def neighbours(
        self, lane_index: LaneIndex, s: float, row: int
    ) -> tuple[RoadObject | None, RoadObject | None]:
        """Stock `neighbour_vehicles` semantics: front = smallest s_v >= s (last row on ties),
        rear = largest s_v < s (first row on ties); the querying object itself excluded."""
        keys, rows = self.sorted_on_lane(lane_index)
        start = bisect_left(keys, s)
        front = None
        i = start
        while i < len(keys) and rows[i] == row:
            i += 1
        if i < len(keys):
            nearest = keys[i]
            while i < len(keys) and keys[i] == nearest:
                if rows[i] != row:
                    front = rows[i]
                i += 1
        rear = None
        j = start - 1
        while j >= 0 and rows[j] == row:
            j -= 1
        if j >= 0:
            nearest = keys[j]
            while j >= 0 and keys[j] == nearest:
                if rows[j] != row:
                    rear = rows[j]
                j -= 1
        return (
            None if front is None else self.objects[front],
            None if rear is None else self.objects[rear],
        )

    def _project(self, lane: AbstractLane) -> tuple[np.ndarray, np.ndarray]:
        if type(lane) is StraightLane:
            delta = self.position - lane.start
            s = delta[:, 0] * lane.direction[0] + delta[:, 1] * lane.direction[1]
            lateral = delta[:, 0] * lane.direction_lateral[0] + delta[:, 1] * lane.direction_lateral[1]
            on = (np.abs(lateral) <= lane.width / 2 + NEIGHBOUR_MARGIN) & (
                (-lane.VEHICLE_LENGTH <= s) & (s < lane.length + lane.VEHICLE_LENGTH)
            )
            return s, on
        coordinates = [lane.local_coordinates(p) for p in self.position]
        s = np.array([c[0] for c in coordinates], dtype=float)
        on = np.array(
            [
                lane.on_lane(p, c[0], c[1], margin=NEIGHBOUR_MARGIN)
                for p, c in zip(self.position, coordinates, strict=True)
            ],
            dtype=bool,
        )
        return s, on


class FastRoadNetwork(RoadNetwork):
    """A `RoadNetwork` whose closest-lane search, called by every vehicle every frame, evaluates
    highway-env's `distance_with_heading` for straight lanes in plain floats (other lanes, such as
    an exit's curve, through their own `distance_with_heading`, as stock does)."""

    _lanes: list[tuple[LaneIndex, AbstractLane, bool]] | None = None
    """Every lane in stock's search order, with whether it is a `StraightLane`."""

    def get_closest_lane_index(self, position: np.ndarray, heading: float | None = None) -> LaneIndex | None:
        """Stock's closest lane (by position and heading); None only on a network without lanes."""
        if heading is None:
            return super().get_closest_lane_index(position, heading)
        lanes = self._lanes
        if lanes is None:
            lanes = self._lanes = [
                ((_from, _to, _id), lane, type(lane) is StraightLane)
                for _from, to_dict in self.graph.items()
                for _to, lane_list in to_dict.items()
                for _id, lane in enumerate(lane_list)
            ]
        x, y = float(position[0]), float(position[1])
        best_index, best = None, None
        for index, lane, straight in lanes:
            if straight:
                dx, dy = x - lane.start[0], y - lane.start[1]
                s = dx * lane.direction[0] + dy * lane.direction[1]
                r = dx * lane.direction_lateral[0] + dy * lane.direction_lateral[1]
                angle = abs(wrap_to_pi(heading - lane.heading))
                distance = abs(r) + max(s - lane.length, 0) + max(0 - s, 0) + angle
            else:
                distance = lane.distance_with_heading(position, heading)
            if best is None or distance < best:
                best_index, best = index, distance
        return best_index


class FastRoad(Road):
    """A `Road` whose neighbour search and collision broad phase are indexed once per frame."""

    _projections: LaneProjections | None = None

    @classmethod
    def adopt(cls, road: Road) -> FastRoad:
        """Turn a freshly built `Road` into a `FastRoad` in place (vehicles keep their reference)."""
        road.__class__ = cls
        road.network.__class__ = FastRoadNetwork
        return road

    def act(self) -> None:
        self._projections = LaneProjections(self)
        try:
            super().act()
        finally:
            self._projections = None

    def neighbour_vehicles(
        self, vehicle: RoadObject, lane_index: LaneIndex | None = None
    ) -> tuple[RoadObject | None, RoadObject | None]:
        projections = self._projections
        row = projections.row.get(id(vehicle)) if projections is not None else None
        if projections is None or row is None or self.neighbour_vehicles_connected_lanes:
            return super().neighbour_vehicles(vehicle, lane_index)
        lane_index = lane_index or vehicle.lane_index
        if not lane_index:
            return None, None
        s = self.network.get_lane(lane_index).local_coordinates(vehicle.position)[0]
        return projections.neighbours(lane_index, s, row)

    def step(self, dt: float) -> None:
        for vehicle in self.vehicles:
            vehicle.step(dt)
        self._collide(dt)

    def _collide(self, dt: float, candidates: np.ndarray | None = None) -> None:
        """Stock's collision loop (each vehicle against the later vehicles, then the objects), over
        the broad phase's candidate pairs only (`_collision_pairs`, unless given)."""
        vehicles, objects = self.vehicles, self.objects
        pairs = (self._collision_pairs(dt) if candidates is None else candidates).tolist()
        if not objects:
            for i, j in pairs:
                vehicles[i].handle_collisions(vehicles[j], dt)
            return
        k = 0
        for i, vehicle in enumerate(vehicles):
            while k < len(pairs) and pairs[k][0] == i:
                vehicle.handle_collisions(vehicles[pairs[k][1]], dt)
                k += 1
            for other in objects:
                vehicle.handle_collisions(other, dt)

    def _collision_pairs(self, dt: float) -> np.ndarray:
        """The pairs (i, j), i < j, of vehicles that pass highway-env's spherical pre-check, in the
        order the stock loop visits them (by i, then j), as an (n, 2) array."""
        count = len(self.vehicles)
        if count < 2:
            return np.empty((0, 2), dtype=int)
        vehicles = self.vehicles
        x, y = np.array([v.position for v in vehicles], dtype=float).T.copy()
        diagonal = np.array([v.diagonal for v in vehicles], dtype=float)
        return broad_phase(x, y, diagonal, np.array([v.speed for v in vehicles], dtype=float), dt)


def broad_phase(
    x: np.ndarray, y: np.ndarray, diagonal: np.ndarray, speed: np.ndarray, dt: float
) -> np.ndarray:
    """The pairs (i, j), i < j, of vehicles at (x, y) [m] of `diagonal` [m] and `speed` [m/s] within
    highway-env's spherical pre-check distance over `dt` [s], by i then j, as an (n, 2) array."""
    first, second = _upper_pairs(len(x))
    distance = np.hypot(x[second] - x[first], y[second] - y[first])
    reach = (diagonal[first] + diagonal[second]) / 2 + speed[first] * dt + BROAD_PHASE_MARGIN
    near = np.flatnonzero(distance <= reach)
    return np.stack([first[near], second[near]], axis=1)


_UPPER_PAIRS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _upper_pairs(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair (i, j), i < j < count, in row-major order (`np.triu_indices`), kept per count."""
    pairs = _UPPER_PAIRS.get(count)
    if pairs is None:
        if len(_UPPER_PAIRS) > 64:
            _UPPER_PAIRS.clear()
        pairs = _UPPER_PAIRS[count] = np.triu_indices(count, k=1)
    return pairs


class FastHighwayEnv(ScenarioTraffic):
    """highway-v0 (with the scenarios' traffic, `stack.sim.traffic`) on a `FastRoad`."""

    def _create_road(self) -> None:
        super()._create_road()
        FastRoad.adopt(self.road)


class FastHighwayEnvFast(HighwayEnvFast):
    """highway-fast-v0 on a `FastRoad`."""

    def _create_road(self) -> None:
        super()._create_road()
        FastRoad.adopt(self.road)


class FastExitEnv(ExitTraffic):
    """exit-v0 (with the stack's drivable starts when asked, `stack.sim.traffic.ExitTraffic`) on a
    `FastRoad`."""

    def _create_road(
        self, road_length: float = 1000, exit_position: float = 400, exit_length: float = 100
    ) -> None:
        super()._create_road(road_length, exit_position, exit_length)
        FastRoad.adopt(self.road)
