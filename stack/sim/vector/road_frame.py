"""One frame of traffic as arrays: every road object's state when `Road.act()` starts, highway-env's
neighbour search for many vehicles at once, and its IDM acceleration evaluated row-wise."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import RoadObject

from stack.sim.fast_road import NEIGHBOUR_MARGIN, LaneProjections, is_kind
from stack.sim.vector.dynamics import idm_accelerations, idm_gap_ratios, idm_inputs
from stack.sim.vector.geometry_kernels import lane_order, neighbour_rows
from stack.sim.vector.lanes import LaneTable
from stack.sim.vector.motion import Moved, columns


class TrafficFrame:
    """Every road object's state at the start of `Road.act()` as arrays, in `LaneProjections` rows:
    s [m] (the same on every lane), r [m] per lane, and per lane the objects highway-env's
    neighbour search counts as on it, in order of s."""

    def __init__(self, projections: LaneProjections, lanes: LaneTable, moved: Moved | None = None) -> None:
        """`moved`, when given, is where the last step left the road's vehicles, the first rows
        (nothing has moved them since): their headings, speeds and lanes are taken from it."""
        objects = projections.objects
        self.projections, self.lanes = projections, lanes
        self.position = projections.position
        lane_row = lanes.row

        def state(o: RoadObject) -> tuple[float, float, float, int]:
            return o.heading, o.speed, getattr(o, "target_speed", 0), lane_row.get(o.lane_index, 0)

        if moved is None:
            self.heading, self.speed, self.target_speed, lane = columns(objects, state)
            self.lane = lane.astype(int)
        else:
            n = len(moved.vehicles)
            others = columns(objects[n:], state) if len(objects) > n else np.empty((4, 0))
            self.heading = np.concatenate([moved.footprints.heading, others[0]])
            self.speed = np.concatenate([moved.footprints.speed, others[1]])
            self.target_speed = np.array([getattr(o, "target_speed", 0) for o in objects], dtype=float)
            self.lane = np.concatenate([moved.lane_row, others[3].astype(int)])
        kinds = {cls: is_kind(cls, Vehicle) for cls in set(map(type, objects))}
        if all(kinds.values()):
            self.is_vehicle = np.ones(len(objects), dtype=bool)
        else:
            self.is_vehicle = np.array([kinds[type(o)] for o in objects], dtype=bool)
        self.direction = np.array((np.cos(self.heading), np.sin(self.heading))).T.copy()
        self.speed_limit = lanes.speed_limit[self.lane]
        self.velocity = self.speed[:, None] * self.direction
        self.s, self.r, self.order, self.sorted_s, self.tied, self.next_on, self.last_before = lane_order(
            np.ascontiguousarray(self.position),
            lanes.start,
            lanes.direction,
            lanes.lateral,
            lanes.length,
            lanes.half_width,
            StraightLane.VEHICLE_LENGTH,
            NEIGHBOUR_MARGIN,
        )

    def row(self, vehicle: RoadObject | None) -> int:
        """The object's row, -1 for none."""
        return -1 if vehicle is None else self.projections.row[id(vehicle)]

    def neighbours(self, me: np.ndarray, lane_rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows of the (front, rear) of the objects in rows `me`, each on its lane of `lane_rows`,
        as `Road.neighbour_vehicles` picks them: front the nearest at s_v >= s, rear the nearest at
        s_v < s, itself excluded (-1 for none)."""
        if self.tied:
            pairs = [
                self.projections.neighbours(self.lanes.indices[lane], float(self.s[row]), row)
                for row, lane in zip(me.tolist(), lane_rows.tolist(), strict=True)
            ]
            return (
                np.array([self.row(front) for front, _ in pairs], dtype=int),
                np.array([self.row(rear) for _, rear in pairs], dtype=int),
            )
        return neighbour_rows(
            me, lane_rows, self.s, self.order, self.sorted_s, self.next_on, self.last_before
        )

    def idm(self, ego: np.ndarray, front: np.ndarray, laws: DriverLaws, evaluator: np.ndarray) -> np.ndarray:
        """`IDMVehicle.acceleration(ego_vehicle=ego, front_vehicle=front)` [m/s^2] per row, for
        the evaluating IDM driver of each pair (its row of `laws` in `evaluator`); rows -1 stand
        for no vehicle (0 without ego); the gap is measured along the ego's lane, as stock does."""
        return self.idm_and_free_road(ego, front, laws, evaluator)[0]

    def idm_and_free_road(
        self, ego: np.ndarray, front: np.ndarray, laws: DriverLaws, evaluator: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """`idm`, and each pair's free-road term [m/s^2] (`IdmRows.idm_and_free_road`)."""
        rows = IdmRows(**{column.name: getattr(self, column.name) for column in fields(IdmRows)})
        return rows.idm_and_free_road(ego, front, laws, evaluator)


@dataclass(frozen=True, eq=False)
class DriverLaws:
    """IDM and MOBIL parameters of a set of drivers, one row each, under the names highway-env's
    `IDMVehicle` gives them (a driver of a population other than highway-env's has its own,
    `stack.sim.drivers`): IDM's exponent `delta`, jam distance `distance_wanted` (centre to centre)
    [m], time gap `time_wanted` [s], maximum acceleration `a_max` [m/s^2] and `braking_term`
    2 sqrt(a b) [m/s^2]; MOBIL's `politeness`, incentive threshold `min_gain` [m/s^2], the most
    braking it imposes `max_braking_imposed` [m/s^2] and its period `lane_change_delay` [s]."""

    delta: np.ndarray
    distance_wanted: np.ndarray
    time_wanted: np.ndarray
    a_max: np.ndarray
    braking_term: np.ndarray
    politeness: np.ndarray
    min_gain: np.ndarray
    max_braking_imposed: np.ndarray
    lane_change_delay: np.ndarray

    @staticmethod
    def of(
        delta: np.ndarray,
        distance_wanted: np.ndarray,
        time_wanted: np.ndarray,
        comfort_acc_max: np.ndarray,
        comfort_acc_min: np.ndarray,
        politeness: np.ndarray,
        min_gain: np.ndarray,
        max_braking_imposed: np.ndarray,
        lane_change_delay: np.ndarray,
    ) -> DriverLaws:
        """The laws of drivers with `IDMVehicle`'s COMFORT_ACC_MAX and COMFORT_ACC_MIN (a and -b
        [m/s^2]): the braking term as highway-env computes it, 2 sqrt(-a b_min)."""
        braking_term = 2 * np.sqrt(-comfort_acc_max * comfort_acc_min)
        return DriverLaws(
            delta,
            distance_wanted,
            time_wanted,
            comfort_acc_max,
            braking_term,
            politeness,
            min_gain,
            max_braking_imposed,
            lane_change_delay,
        )


@dataclass(frozen=True, eq=False)
class IdmRows:
    """What IDM reads of every row of a set of road objects: whether it is a vehicle, its speed,
    target speed and lane speed limit [m/s] (NaN: none), s along the lanes [m], velocity [m/s]
    and heading direction (rows, 2)."""

    is_vehicle: np.ndarray
    speed: np.ndarray
    target_speed: np.ndarray
    speed_limit: np.ndarray
    s: np.ndarray
    velocity: np.ndarray
    direction: np.ndarray

    def idm(self, ego: np.ndarray, front: np.ndarray, laws: DriverLaws, evaluator: np.ndarray) -> np.ndarray:
        """`IDMVehicle.acceleration(ego_vehicle=ego, front_vehicle=front)` [m/s^2] per pair of rows
        (-1: none), evaluated by the IDM driver in row `evaluator` of `laws` per pair: compiled
        arithmetic around numpy's powers and dot products (highway-env's bits)."""
        return self.idm_and_free_road(ego, front, laws, evaluator)[0]

    def idm_and_free_road(
        self, ego: np.ndarray, front: np.ndarray, laws: DriverLaws, evaluator: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """`idm`, and each pair's free-road term [m/s^2] (its IDM behind no leader), bit for bit
        what `idm` gives for the ego with front -1."""
        valid, base, led, relative, heading, gap, led_speed = idm_inputs(
            ego,
            front,
            self.is_vehicle,
            self.speed,
            self.target_speed,
            self.speed_limit,
            self.s,
            self.velocity,
            self.direction,
        )
        free_power = np.power(base, laws.delta[evaluator[valid]])
        closing = np.vecdot(relative, heading)
        ratio = idm_gap_ratios(
            closing,
            gap,
            led_speed,
            valid,
            led,
            evaluator,
            laws.distance_wanted,
            laws.time_wanted,
            laws.braking_term,
        )
        gap_power = np.power(ratio, 2)
        return idm_accelerations(len(ego), valid, free_power, led, gap_power, evaluator, laws.a_max)
