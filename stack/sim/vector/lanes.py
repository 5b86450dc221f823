"""Lanes as arrays: the `vector` backend's view of a road made of parallel, axis-aligned straight
lanes that start level with each other (highway-v0's). On such a road every lane coordinate is exact
in any operation order (each product is by 0 or +-1), and an object's longitudinal coordinate is the
same on every lane."""

from __future__ import annotations

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.road.road import RoadNetwork

from stack.sim.fast_road import LaneIndex
from stack.sim.vector.geometry_kernels import closest_lanes


def clip(x: np.ndarray, bound: float) -> np.ndarray:
    """`np.clip(x, -bound, bound)` for a `bound` > 0, as two ufuncs: the same bits (NaN stays NaN;
    no tie with a bound of the other sign of zero can arise), without `np.clip`'s dispatch."""
    return np.minimum(np.maximum(x, -bound), bound)


def _unit_axis(vector: np.ndarray) -> bool:
    return bool(sorted(np.abs(vector).tolist()) == [0.0, 1.0])


class LaneTable:
    """Every lane of the network, in the order `RoadNetwork.get_closest_lane_index` visits them."""

    def __init__(self, network: RoadNetwork) -> None:
        self.indices: list[LaneIndex] = []
        self.lanes: list[StraightLane] = []
        for _from, to_dict in network.graph.items():
            for _to, lane_list in to_dict.items():
                for _id, lane in enumerate(lane_list):
                    self.indices.append((_from, _to, _id))
                    self.lanes.append(lane)
        self.row = {index: i for i, index in enumerate(self.indices)}
        self.lane_id = np.array([index[2] for index in self.indices], dtype=int)
        self.start = np.array([lane.start for lane in self.lanes], dtype=float)
        self.direction = np.array(self.lanes[0].direction, dtype=float)
        self.lateral = np.array([lane.direction_lateral for lane in self.lanes], dtype=float)
        self.length = np.array([lane.length for lane in self.lanes], dtype=float)
        self.half_width = np.array([lane.width for lane in self.lanes], dtype=float) / 2
        self.heading = np.array([lane.heading for lane in self.lanes], dtype=float)
        self.forbidden = np.array([lane.forbidden for lane in self.lanes], dtype=bool)
        self.speed_limit = np.array(
            [np.nan if lane.speed_limit is None else lane.speed_limit for lane in self.lanes], dtype=float
        )
        self.limited = not bool(np.isnan(self.speed_limit).any())
        """Every lane has a speed limit."""

    @staticmethod
    def fit(network: RoadNetwork) -> LaneTable | None:
        """The table of `network`, or None when its lanes are not all parallel, axis-aligned,
        straight and level at their start."""
        lanes = [lane for to_dict in network.graph.values() for ls in to_dict.values() for lane in ls]
        if not lanes or any(type(lane) is not StraightLane for lane in lanes):
            return None
        direction = lanes[0].direction
        level = {float(np.dot(lane.start, direction)) for lane in lanes}
        parallel = all(np.array_equal(lane.direction, direction) for lane in lanes)
        axes = all(_unit_axis(lane.direction) and _unit_axis(lane.direction_lateral) for lane in lanes)
        return LaneTable(network) if parallel and axes and len(level) == 1 else None

    def reachable(self, rows: np.ndarray, s: np.ndarray, r: np.ndarray) -> np.ndarray:
        """highway-env's `is_reachable_from` of lanes `rows` for objects at (s, r) on them."""
        near = np.abs(r) <= 2 * (2 * self.half_width[rows])
        ahead = (0 <= s) & (s < self.length[rows] + StraightLane.VEHICLE_LENGTH)
        return ~self.forbidden[rows] & near & ahead

    def closest(self, x: np.ndarray, y: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """Row of each vehicle's closest lane by highway-env's `distance_with_heading` (first on ties),
        vehicles at (x, y) [m] heading `heading` [rad]."""
        start, direction, lateral = self.start, self.direction, self.lateral
        return closest_lanes(x, y, heading, start, direction, lateral, self.length, self.heading)
