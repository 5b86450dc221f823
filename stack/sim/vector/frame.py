"""One frame of traffic as arrays: every road object's state when `Road.act()` starts, highway-env's
neighbour search for many vehicles at once, and its IDM acceleration evaluated row-wise."""

from __future__ import annotations

import numpy as np
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import RoadObject

from stack.sim.fast_road import LaneIndex, LaneProjections
from stack.sim.vector.lanes import LaneTable, not_zero


class TrafficFrame:
    """Every road object's state at the start of `Road.act()` as arrays, in `LaneProjections` rows,
    and highway-env's IDM evaluated on rows of them."""

    def __init__(self, projections: LaneProjections, lanes: LaneTable) -> None:
        objects = projections.objects
        self.projections, self.lanes = projections, lanes
        self.position = projections.position
        self.heading = np.array([o.heading for o in objects], dtype=float)
        self.speed = np.array([o.speed for o in objects], dtype=float)
        self.target_speed = np.array([getattr(o, "target_speed", 0) for o in objects], dtype=float)
        self.is_vehicle = np.array([isinstance(o, Vehicle) for o in objects], dtype=bool)
        self.lane = np.array([lanes.row.get(o.lane_index, 0) for o in objects], dtype=int)
        self.direction = np.stack([np.cos(self.heading), np.sin(self.heading)], axis=1)
        self.velocity = self.speed[:, None] * self.direction
        self._lanes_sorted: dict[LaneIndex, tuple[np.ndarray, np.ndarray]] = {}

    def row(self, vehicle: RoadObject | None) -> int:
        """The object's row, -1 for none."""
        return -1 if vehicle is None else self.projections.row[id(vehicle)]

    def neighbours(
        self, vehicles: list[IDMVehicle], lane_indices: list[LaneIndex]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rows of each vehicle's (front, rear) on its lane of `lane_indices`, as
        `Road.neighbour_vehicles` picks them (-1 for none)."""
        me = np.array([self.row(v) for v in vehicles], dtype=int)
        s, _ = self.lanes.coordinates(np.array([self.lanes.row[i] for i in lane_indices]), self.position[me])
        front, rear = np.full(len(me), -1), np.full(len(me), -1)
        queries: dict[LaneIndex, list[int]] = {}
        for q, lane_index in enumerate(lane_indices):
            queries.setdefault(lane_index, []).append(q)
        for lane_index, ks in queries.items():
            keys, rows = self._sorted(lane_index)
            k = np.array(ks)
            if not len(keys):
                continue
            if len(keys) > 1 and np.any(keys[1:] == keys[:-1]):
                for q in ks:
                    pair = self.projections.neighbours(lane_index, float(s[q]), int(me[q]))
                    front[q], rear[q] = self.row(pair[0]), self.row(pair[1])
                continue
            start = np.searchsorted(keys, s[k], side="left")
            own = (start < len(keys)) & (rows[np.minimum(start, len(keys) - 1)] == me[k])
            ahead = start + own
            front[k] = np.where(ahead < len(keys), rows[np.minimum(ahead, len(keys) - 1)], -1)
            rear[k] = np.where(start > 0, rows[np.maximum(start - 1, 0)], -1)
        return front, rear

    def _sorted(self, lane_index: LaneIndex) -> tuple[np.ndarray, np.ndarray]:
        cached = self._lanes_sorted.get(lane_index)
        if cached is None:
            keys, rows = self.projections.sorted_on_lane(lane_index)
            cached = self._lanes_sorted[lane_index] = (np.array(keys, dtype=float), np.array(rows, dtype=int))
        return cached

    def idm(self, ego: np.ndarray, front: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """`IDMVehicle.acceleration(ego_vehicle=ego, front_vehicle=front)` [m/s^2] per row, for an
        evaluating IDM vehicle of exponent `delta`; rows -1 stand for no vehicle (0 without ego);
        the gap is measured along the ego's lane, as stock does."""
        acceleration = np.zeros(len(ego))
        valid = (ego >= 0) & self.is_vehicle[ego]
        if not valid.any():
            return acceleration
        e, f, delta = ego[valid], front[valid], delta[valid]
        lane, speed = self.lane[e], self.speed[e]
        limit = self.lanes.speed_limit[lane]
        desired = np.where(np.isnan(limit), self.target_speed[e], np.clip(self.target_speed[e], 0, limit))
        free = IDMVehicle.COMFORT_ACC_MAX * (
            1 - np.power(np.maximum(speed, 0) / np.abs(not_zero(desired)), delta)
        )
        led = f >= 0
        if led.any():
            e, f, lane, led_speed = e[led], f[led], lane[led], speed[led]
            gap = (
                self.lanes.coordinates(lane, self.position[f])[0]
                - self.lanes.coordinates(lane, self.position[e])[0]
            )
            relative = np.ascontiguousarray(self.velocity[e] - self.velocity[f])
            closing = np.vecdot(relative, np.ascontiguousarray(self.direction[e]))
            ab = -IDMVehicle.COMFORT_ACC_MAX * IDMVehicle.COMFORT_ACC_MIN
            desired_gap = (
                IDMVehicle.DISTANCE_WANTED
                + led_speed * IDMVehicle.TIME_WANTED
                + led_speed * closing / (2 * np.sqrt(ab))
            )
            free[led] -= IDMVehicle.COMFORT_ACC_MAX * np.power(desired_gap / not_zero(gap), 2)
        acceleration[valid] = free
        return acceleration
