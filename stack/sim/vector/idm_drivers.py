"""The IDM drivers of one frame of the `vector` road (`Drivers`: their rows, constants and
lane-change state) and the habits that change their accelerations (`delayed`, `yield_and_brake`:
the laws of `stack.sim.vector.habits` applied to a frame's drivers)."""

from __future__ import annotations

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle

from stack.sim.vector.habits import (
    HabitColumns,
    SeenPast,
    delayed_accelerations,
    sudden_accelerations,
    yielders,
    yielding,
)
from stack.sim.vector.road_frame import DriverLaws, TrafficFrame


class Drivers:
    """The IDM drivers of a frame: their rows, constants, lane-change state, and their own lane's
    front and rear."""

    own_acceleration: np.ndarray
    """IDM acceleration [m/s^2] behind the own lane's leader, per driver (set by `_mobil`)."""
    own_free_road: np.ndarray
    """Its free-road term [m/s^2] (IDM behind no leader), per driver (set by `_mobil`)."""
    habits: HabitColumns | None = None
    """The drivers' habits, None when none has one (`VectorRoad._read_habits` sets the rest)."""
    frame_index: int = 0
    ego_row: int = -1
    intent: int = -1

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
        self.length = constants[0]
        self.laws = DriverLaws.of(*constants[1:])
        self.comfort_acc_min = constants[5]
        self.everyone = np.arange(len(drivers))
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


def delayed(plan: Drivers, seen: SeenPast, acceleration: np.ndarray) -> None:
    """The own-lane IDM of the drivers that act on a delayed view, in place
    (`delayed_accelerations` over the road's `seen` past)."""
    frame, me, laws = plan.frame, plan.me, plan.laws
    assert plan.habits is not None
    delayed_accelerations(
        acceleration, plan.everyone, me, plan.own_front, seen.s.shape[2], plan.habits.delay_frames,
        seen.s, seen.speed, seen.pushed, plan.own_free_road, frame.speed[me], laws.a_max,
        laws.distance_wanted, laws.time_wanted, laws.braking_term,
    )  # fmt: skip


def yield_and_brake(plan: Drivers, acceleration: np.ndarray) -> None:
    """The yielding drivers behind the ego's lane change (`yielders`, `yielding`) and the sudden
    brakings (`sudden_accelerations`), in place."""
    habits, frame, me = plan.habits, plan.frame, plan.me
    assert habits is not None
    if plan.ego_row >= 0 and plan.intent >= 0 and habits.yields:
        yield_now = yielders(
            habits.yields_to_ego,
            frame.lane[me],
            plan.intent,
            frame.s[me],
            frame.s[plan.ego_row],
        ).nonzero()[0]
        if len(yield_now):
            ego = np.full(len(yield_now), plan.ego_row)
            behind_ego = frame.idm(me[yield_now], ego, plan.laws, yield_now)
            acceleration[yield_now] = yielding(
                acceleration[yield_now], behind_ego, plan.comfort_acc_min[yield_now]
            )
    if habits.brakes_suddenly:
        sudden_accelerations(
            acceleration, plan.everyone, np.full(len(me), plan.frame_index), habits.key,
            habits.sudden_braking_chance, habits.sudden_braking_frames, habits.sudden_braking_mps2,
        )  # fmt: skip


def abort_contested_change(driver: IDMVehicle, vehicles: list[Vehicle]) -> None:
    """`IDMVehicle.change_lane_policy` for a `driver` whose lane change runs, as stock decides it:
    back to its own lane when another controlled vehicle of `vehicles`, not in the target lane, is
    changing into it and lies ahead closer than the driver's desired gap. Stock's conditions, the
    cheapest first (the target lane's comparison; the ABC `isinstance` last, for the few left; the
    desired gap only for a vehicle ahead)."""
    target = driver.target_lane_index
    if driver.lane_index[:2] != target[:2]:
        return
    for v in vehicles:
        if (
            getattr(v, "target_lane_index", None) == target
            and v is not driver
            and v.lane_index != target
            and isinstance(v, ControlledVehicle)
        ):
            d = driver.lane_distance_to(v)
            if 0 < d and d < driver.desired_gap(driver, v):
                driver.target_lane_index = driver.lane_index
                break
