"""Lanes as arrays: the `vector` backend's view of a road whose lanes are all axis-aligned straight
lanes (highway-v0's), where lane coordinates are exact in any operation order."""

from __future__ import annotations

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.road.road import RoadNetwork

from stack.sim.fast_road import LaneIndex

NOT_ZERO = 1e-2
"""highway-env's `utils.not_zero` threshold [same unit as the value]."""


def not_zero(x: np.ndarray) -> np.ndarray:
    return np.where(np.abs(x) > NOT_ZERO, x, np.where(x >= 0, NOT_ZERO, -NOT_ZERO))


def wrap_to_pi(x: np.ndarray) -> np.ndarray:
    return ((x + np.pi) % (2 * np.pi)) - np.pi


class LaneTable:
    """Every lane of a network whose lanes are all axis-aligned `StraightLane`s, as arrays, in the
    order `RoadNetwork.get_closest_lane_index` visits them."""

    def __init__(self, network: RoadNetwork) -> None:
        self.indices: list[LaneIndex] = []
        self.lanes: list[StraightLane] = []
        for _from, to_dict in network.graph.items():
            for _to, lane_list in to_dict.items():
                for _id, lane in enumerate(lane_list):
                    self.indices.append((_from, _to, _id))
                    self.lanes.append(lane)
        self.row = {index: i for i, index in enumerate(self.indices)}
        self.start = np.array([lane.start for lane in self.lanes], dtype=float)
        self.direction = np.array([lane.direction for lane in self.lanes], dtype=float)
        self.lateral = np.array([lane.direction_lateral for lane in self.lanes], dtype=float)
        self.length = np.array([lane.length for lane in self.lanes], dtype=float)
        self.heading = np.array([lane.heading for lane in self.lanes], dtype=float)
        self.speed_limit = np.array(
            [np.nan if lane.speed_limit is None else lane.speed_limit for lane in self.lanes], dtype=float
        )

    @staticmethod
    def fit(network: RoadNetwork) -> LaneTable | None:
        lanes = [lane for to_dict in network.graph.values() for ls in to_dict.values() for lane in ls]
        axis_aligned = all(
            type(lane) is StraightLane
            and set(np.abs(lane.direction)) <= {0.0, 1.0}
            and set(np.abs(lane.direction_lateral)) <= {0.0, 1.0}
            for lane in lanes
        )
        return LaneTable(network) if lanes and axis_aligned else None

    def coordinates(self, rows: np.ndarray, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s, r) [m] of each `position` on lane `rows` (element-wise)."""
        delta = position - self.start[rows]
        direction, lateral = self.direction[rows], self.lateral[rows]
        s = delta[:, 0] * direction[:, 0] + delta[:, 1] * direction[:, 1]
        r = delta[:, 0] * lateral[:, 0] + delta[:, 1] * lateral[:, 1]
        return s, r

    def closest(self, position: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """Row of each vehicle's closest lane by highway-env's `distance_with_heading` (first on ties)."""
        delta = position[:, None, :] - self.start[None, :, :]
        s = delta[..., 0] * self.direction[:, 0] + delta[..., 1] * self.direction[:, 1]
        r = delta[..., 0] * self.lateral[:, 0] + delta[..., 1] * self.lateral[:, 1]
        angle = np.abs(wrap_to_pi(heading[:, None] - self.heading[None, :]))
        distance = np.abs(r) + np.maximum(s - self.length, 0) + np.maximum(0 - s, 0) + angle
        return np.argmin(distance, axis=1)
