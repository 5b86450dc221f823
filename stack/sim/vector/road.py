"""The `vector` simulation backend: highway-env's traffic behaviours computed for all vehicles of a
frame at once, with trajectories identical to stock.

A `FastRoad` frame still runs highway-env's per-vehicle Python: `IDMVehicle.act` (IDM, the steering
controller) and `Vehicle.step` (kinematic integration, closest-lane search). `VectorRoad` keeps
highway-env's vehicle objects as the state of record and writes every step back to them, but each
phase reads the vehicles' state from the arrays the previous one computed (nothing moves a vehicle in
between; their constants are kept while the same vehicles drive, `motion.KeptColumns`), and computes
the continuous parts as array operations over the vehicles, in the stock operation order:

- act: the discrete decisions of the `IDMVehicle`s that act this frame (`follow_road` at a lane's
  end, `change_lane_policy`: the MOBIL evaluation due every 1 s, the abort of a contested change) run
  per vehicle in the stock order, since one vehicle's decision is read by the next one's; MOBIL's
  incentive and safety of the due ones, the steering controller and the IDM accelerations (own lane
  and target lane) of all of them at once;
- step: clipping, the kinematic bicycle, impacts and the closest lane of every vehicle at once, then
  stock's collision test on the pairs that could touch (`motion.close_pairs`).

The arithmetic runs as numba kernels (`stack.sim.vector.kernels` for the geometry,
`stack.sim.vector.dynamics` for the vehicles) between numpy's transcendental calls and dot products,
which stay in numpy (highway-env's bits).

Identity rests on four facts checked in `tests/test_sim_backends.py`: numpy's transcendental ufuncs
give the same bits for an array as for each of its elements; `np.vecdot` computes a 2-vector dot
product exactly as `np.dot` (which, through BLAS, rounds differently from `a0*b0 + a1*b1`); lane
coordinates on lanes whose direction is axis-aligned are exact in any operation order; numba's sums,
products, divisions and float modulo are numpy's (no contraction into multiply-adds). Roads with
other lanes (a curved exit, `neighbour_vehicles_connected_lanes`) run as `FastRoad`.
"""

from __future__ import annotations

from operator import attrgetter

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import RoadObject

from stack.sim.fast_road import FastRoad, LaneIndex, LaneProjections
from stack.sim.traffic import IDM_DRIVERS, ScenarioTraffic
from stack.sim.vector.dynamics import steering_angles
from stack.sim.vector.frame import TrafficFrame
from stack.sim.vector.lanes import LaneTable, clip
from stack.sim.vector.motion import (
    MOVER_CONSTANTS,
    Footprints,
    FrameActed,
    KeptColumns,
    Moved,
    close_pairs,
    move,
    same_objects,
    steps_like_vehicle,
)


def _plain_velocity(cls: type) -> bool:
    """Whether objects of `cls` move along their heading at their speed (the vectorised kinematics)."""
    return cls.velocity is Vehicle.velocity or cls.velocity is RoadObject.velocity  # type: ignore[attr-defined]


class VectorRoad(FastRoad):
    """A `FastRoad` whose IDM/MOBIL traffic and kinematics run as array operations (module docstring)."""

    _lanes: LaneTable | None | bool = False
    moved: Moved | None = None
    """Where the last step left every vehicle (`take_moved`)."""
    stepped: Moved | None = None
    """The same, kept for the next act."""
    acted: FrameActed | None = None
    """What the last act left for the step that follows it."""
    mover_constants: KeptColumns | None = None
    driver_constants: KeptColumns | None = None
    """The movers' `MOVER_CONSTANTS` and the drivers' `DRIVER_CONSTANTS`, kept from frame to frame."""

    def _lane_table(self) -> LaneTable | None:
        if self._lanes is False:
            self._lanes = LaneTable.fit(self.network)
        lanes = self._lanes
        assert lanes is not True
        if lanes is None or self.neighbour_vehicles_connected_lanes:
            return None
        plain = all(map(_plain_velocity, set(map(type, self.vehicles))))
        return lanes if plain else None

    def act(self) -> None:
        self.acted = None
        lanes = self._lane_table()
        if lanes is None:
            super().act()
            return
        stepped, self.stepped = self.stepped, None
        if stepped is not None and not same_objects(stepped.vehicles, self.vehicles):
            stepped = None
        position = None if stepped is None else np.stack([stepped.footprints.x, stepped.footprints.y], axis=1)
        self._projections = projections = LaneProjections(self, position)
        try:
            frame = TrafficFrame(projections, lanes, stepped if projections.vehicles_first else None)
            drivers, places, others = [], [], []
            for place, vehicle in enumerate(self.vehicles):
                if type(vehicle) in IDM_DRIVERS and not vehicle.crashed:
                    drivers.append(vehicle)
                    places.append(place)
                else:
                    others.append((place, -1))
            if not drivers:
                for vehicle in self.vehicles:
                    vehicle.act()
                return
            self.driver_constants = KeptColumns.of(drivers, DRIVER_CONSTANTS, self.driver_constants)
            plan = Drivers(drivers, places, frame, self.driver_constants.rows)
            at_lane_end = plan.at_lane_end()
            decisions = self._mobil(plan, ~at_lane_end)
            may_change = plan.enable_lane_change & (plan.timer_due | ~plan.on_target)
            acting = set(decisions).union((at_lane_end | may_change).nonzero()[0].tolist())
            retargeted = []
            for place, k in sorted(others + [(places[k], k) for k in acting]):
                vehicle = self.vehicles[place]
                if k < 0:
                    vehicle.act()
                    continue
                if k in decisions:
                    vehicle.timer = 0
                    if decisions[k]:
                        vehicle.target_lane_index = decisions[k]
                        retargeted.append(k)
                    continue
                if at_lane_end[k]:
                    vehicle.follow_road()
                    retargeted.append(k)
                due = vehicle.LANE_CHANGE_DELAY < vehicle.timer
                if vehicle.enable_lane_change and (due or vehicle.lane_index != vehicle.target_lane_index):
                    vehicle.change_lane_policy()
                    retargeted.append(k)
            plan.retarget(retargeted)
            steering, acceleration = self._drive(plan)
            if projections.vehicles_first:
                n = len(self.vehicles)
                self.acted = FrameActed(
                    list(self.vehicles),
                    frame.speed[:n],
                    frame.heading[:n],
                    frame.position[:n],
                    np.array(places, dtype=int),
                    steering,
                    acceleration,
                )
        finally:
            self._projections = None

    def _mobil(self, plan: Drivers, free: np.ndarray) -> dict[int, LaneIndex | None]:
        """`change_lane_policy`'s outcome for the drivers due to decide (not those not `free`: they
        follow the road onto the next lane), keyed by their position in `plan.drivers`: the side
        lane MOBIL picks (the last one that passes, as stock overwrites), or None to keep the lane.
        Also evaluates every driver's IDM acceleration behind its own leader
        (`plan.own_acceleration`), in the same array call."""
        frame, drivers = plan.frame, plan.drivers
        deciding = plan.timer_due & free & plan.enable_lane_change & plan.on_target & ~plan.routed
        due = deciding.nonzero()[0].tolist()
        decisions: dict[int, LaneIndex | None] = dict.fromkeys(due)
        pairs = [
            (k, side)
            for k in due
            if abs(drivers[k].speed) >= 1
            for side in self.network.side_lanes(drivers[k].lane_index)
        ]
        own = plan.me, plan.own_front, plan.delta, plan.jam
        if pairs:
            index = np.array([k for k, _ in pairs], dtype=int)
            sides = np.array([frame.lanes.row[side] for _, side in pairs], dtype=int)
            me = plan.me[index]
            reachable = frame.lanes.reachable(sides, frame.s[me], frame.r[sides, me])
            pairs = [pair for pair, keep in zip(pairs, reachable.tolist(), strict=True) if keep]
            index, sides, me = index[reachable], sides[reachable], me[reachable]
        if not pairs:
            plan.own_acceleration = frame.idm(*own)
            return decisions
        new_front, new_rear = frame.neighbours(me, sides)
        own_front, own_rear = plan.own_front[index], plan.own_rear[index]
        blocks = 6
        delta = np.concatenate([plan.delta[index]] * blocks + [plan.delta])
        jam = np.concatenate([plan.jam[index]] * blocks + [plan.jam])
        egos = np.concatenate([new_rear, new_rear, me, me, own_rear, own_rear, plan.me])
        leaders = np.concatenate([new_front, me, new_front, own_front, me, own_front, plan.own_front])
        a = frame.idm(egos, leaders, delta, jam)
        plan.own_acceleration = a[blocks * len(me) :]
        new_rear_a, new_rear_pred_a, self_pred_a, self_a, own_rear_a, own_rear_pred_a = a[
            : blocks * len(me)
        ].reshape(blocks, -1)
        gain = (
            self_pred_a
            - self_a
            + IDMVehicle.POLITENESS * (new_rear_pred_a - new_rear_a + own_rear_pred_a - own_rear_a)
        )
        unsafe = new_rear_pred_a < -IDMVehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED
        accept = ~unsafe & ~(gain < IDMVehicle.LANE_CHANGE_MIN_ACC_GAIN)
        for (k, side), yes in zip(pairs, accept.tolist(), strict=True):
            if yes:
                decisions[k] = side
        return decisions

    @staticmethod
    def _drive(plan: Drivers) -> tuple[np.ndarray, np.ndarray]:
        """`IDMVehicle.act`'s steering [rad] and IDM acceleration [m/s^2] of every driver, after its
        decisions: set as their actions, and returned."""
        frame, drivers, me = plan.frame, plan.drivers, plan.me
        lanes = frame.lanes
        heading, speed, target = frame.heading[me], frame.speed[me], plan.target
        changing = frame.lane[me] != target

        steering = steering_angles(frame.r[target, me], lanes.heading[target], heading, plan.length, speed)

        acceleration = plan.own_acceleration
        if changing.any():
            movers = changing.nonzero()[0]
            target_front, _ = frame.neighbours(me[movers], target[movers])
            on_target = frame.idm(me[movers], target_front, plan.delta[movers], plan.jam[movers])
            acceleration[movers] = np.where(on_target < acceleration[movers], on_target, acceleration[movers])
        acceleration = clip(acceleration, IDMVehicle.ACC_MAX)
        for v, steer, accel in zip(drivers, steering, acceleration, strict=True):
            v.action = {"steering": steer, "acceleration": accel}
        return steering, acceleration

    def step(self, dt: float) -> None:
        lanes = self._lane_table()
        if lanes is None:
            super().step(dt)
            return
        acted, self.acted = self.acted, None
        kinds = {cls: steps_like_vehicle(cls) for cls in set(map(type, self.vehicles))}
        if all(kinds.values()):
            movers = list(self.vehicles)
        else:
            movers, acted = [], None
            for vehicle in self.vehicles:
                if kinds[type(vehicle)]:
                    movers.append(vehicle)
                else:
                    vehicle.step(dt)
        constants = None
        if acted is not None and same_objects(acted.vehicles, movers):
            self.mover_constants = KeptColumns.of(movers, MOVER_CONSTANTS, self.mover_constants)
            constants = self.mover_constants.rows
        moved = move(movers, lanes, dt, self.record_history, acted, constants) if movers else None
        self.moved = self.stepped = moved if moved is not None and len(movers) == len(self.vehicles) else None
        if self.moved is not None and len(movers) >= 2:
            self._collide(dt, close_pairs(self.moved.footprints, dt))
        else:
            self._collide(dt)

    def take_moved(self) -> Moved | None:
        """Where the last frame's step left every vehicle, if it moved them all, once: read right
        after the step (collisions change crash flags and impacts only), before anything else can
        move a vehicle."""
        moved, self.moved = self.moved, None
        return moved

    def _collision_pairs(self, dt: float) -> np.ndarray:
        """The pairs `close_pairs` keeps."""
        if len(self.vehicles) < 2:
            return super()._collision_pairs(dt)
        return close_pairs(Footprints.of(self.vehicles), dt)


DRIVER_CONSTANTS = attrgetter("LENGTH", "DELTA", "DISTANCE_WANTED")
"""A driver's LENGTH [m], IDM exponent DELTA and jam distance DISTANCE_WANTED [m]."""


class Drivers:
    """The IDM drivers of a frame: their rows, constants, lane-change state, and their own lane's
    front and rear."""

    own_acceleration: np.ndarray
    """IDM acceleration [m/s^2] behind the own lane's leader, per driver (set by `_mobil`)."""

    def __init__(
        self, drivers: list[IDMVehicle], places: list[int], frame: TrafficFrame, constants: np.ndarray
    ) -> None:
        """`places`: the drivers' places in the road's vehicles; `constants`: their `DRIVER_CONSTANTS`."""
        self.drivers, self.frame = drivers, frame
        projections, lane_row = frame.projections, frame.lanes.row
        if projections.vehicles_first:
            self.me = np.array(places, dtype=int)
        else:
            self.me = np.array([projections.row[id(v)] for v in drivers], dtype=int)
        self.target = np.array([lane_row[v.target_lane_index] for v in drivers], dtype=int)
        self.length, self.delta, self.jam = constants
        self.timer_due = np.array([v.LANE_CHANGE_DELAY < v.timer for v in drivers], dtype=bool)
        self.enable_lane_change = np.array([v.enable_lane_change for v in drivers], dtype=bool)
        self.on_target = np.array([v.lane_index == v.target_lane_index for v in drivers], dtype=bool)
        self.routed = np.array([bool(v.route) for v in drivers], dtype=bool)
        """Per driver: its lane-change timer is past `LANE_CHANGE_DELAY`; it may change lane; it is in
        its target lane; it follows a route."""
        self.own_front, self.own_rear = frame.neighbours(self.me, frame.lane[self.me])

    def retarget(self, drivers: list[int]) -> None:
        """Re-read the target lanes of `drivers` (positions in `self.drivers`) after their decisions."""
        lane_row = self.frame.lanes.row
        for k in drivers:
            self.target[k] = lane_row[self.drivers[k].target_lane_index]

    def at_lane_end(self) -> np.ndarray:
        """Per driver, whether `follow_road` moves it on to the next lane."""
        frame = self.frame
        return frame.s[self.me] > frame.lanes.length[self.target] - StraightLane.VEHICLE_LENGTH / 2


class VectorHighwayEnv(ScenarioTraffic):
    """highway-v0 (with the scenarios' traffic, `stack.sim.traffic`) on a `VectorRoad`."""

    def _create_road(self) -> None:
        super()._create_road()
        VectorRoad.adopt(self.road)
