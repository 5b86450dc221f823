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

The arithmetic runs as numba kernels (`stack.sim.vector.geometry_kernels` for the geometry,
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

from operator import attrgetter, itemgetter

import numpy as np
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import RoadObject

from stack.sim.fast_road import FastRoad, LaneIndex, LaneProjections
from stack.sim.traffic import IDM_DRIVERS, ScenarioTraffic
from stack.sim.vector.dynamics import mobil_verdicts, steering_angles
from stack.sim.vector.habits import (
    HabitColumns,
    SeenPast,
    unseen_ego,
)
from stack.sim.vector.idm_drivers import Drivers, abort_contested_change, delayed, yield_and_brake
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
from stack.sim.vector.road_frame import TrafficFrame


def _plain_velocity(cls: type) -> bool:
    """Whether objects of `cls` move along their heading at their speed (the vectorised kinematics)."""
    return cls.velocity is Vehicle.velocity or cls.velocity is RoadObject.velocity  # type: ignore[attr-defined]


class VectorRoad(FastRoad):
    """A `FastRoad` whose IDM/MOBIL traffic and kinematics run as array operations (module docstring).

    It keeps what one frame computed for the next only where the next frame would read the same
    bits again, each cache checked against the vehicles it was made of before it is used."""

    _network_lanes: LaneTable | None | bool = False
    """The road network's lanes as arrays (`LaneTable.fit`), fitted at the first act or step: False
    until then, None when a lane is not one the table holds. Valid for the road's life: highway-env
    builds a new road, with a new network, at every reset, and never edits a network."""
    left_by_step: Moved | None = None
    """Where the last step left every vehicle, read by the next act instead of the vehicles'
    attributes (the step wrote those bits there). Taken once; valid only if the road still holds
    the vehicles it moved, in the same order (vehicles may be added or removed between frames):
    nothing moves a vehicle between a step and the next act."""
    acted_for_step: FrameActed | None = None
    """What this frame's act read of the vehicles and gave the drivers, for the step right after it:
    cleared by every act, taken by the step, which uses it only if it moves the very vehicles the
    act read (a non-kinematic vehicle steps by itself)."""
    driver_constants: KeptColumns | None = None
    mover_constants: KeptColumns | None = None
    """The drivers' `DRIVER_CONSTANTS` and the movers' `MOVER_CONSTANTS`, kept from frame to frame:
    class constants, fixed when a vehicle is made, so valid while the same vehicles, in the same
    order, drive (`KeptColumns.of` reads them afresh otherwise)."""
    moved: Moved | None = None
    """Where the last step left every vehicle, for the adapter's snapshot (`take_moved`)."""
    ego: Vehicle | None = None
    """The ego (set by the env at reset): what a blind driver does not see and a yielding one yields to."""
    ego_intent_lane: int = -1
    """The lane (row of the road's lanes) the ego shows it is changing into, -1 for none
    (`HighwayAdapter.show_intent`): what a yielding driver reads."""
    acts: int = 0
    """Frames acted since the road was made (at reset): the clock of the sudden brakings."""
    seen: SeenPast | None = None
    """Every row's past s and speed, kept while a driver acts on a delayed view."""
    habit_columns: tuple[list[IDMVehicle], HabitColumns] | None = None
    """The drivers' habits, kept while the same drivers, in the same order, act."""

    def _lane_table(self) -> LaneTable | None:
        """The network's `LaneTable`, or None when this frame runs as `FastRoad` (a lane the table
        cannot hold, connected-lane neighbours, or a vehicle that does not move along its heading)."""
        if self._network_lanes is False:
            self._network_lanes = LaneTable.fit(self.network)
        lanes = self._network_lanes
        assert lanes is not True
        if lanes is None or self.neighbour_vehicles_connected_lanes:
            return None
        plain = all(map(_plain_velocity, set(map(type, self.vehicles))))
        return lanes if plain else None

    def act(self) -> None:
        """Stock `Road.act` for every vehicle, in phases: read the frame (from the last step where it
        is valid), then `_act_in` it; the lane projections it indexes serve the per-vehicle calls
        (`neighbour_vehicles`) of this act only."""
        self.acted_for_step = None
        self.acts += 1
        lanes = self._lane_table()
        if lanes is None:
            super().act()
            return
        moved = self._take_left_by_step()
        position = None if moved is None else np.stack([moved.footprints.x, moved.footprints.y], axis=1)
        self._projections = projections = LaneProjections(self, position)
        try:
            self._act_in(TrafficFrame(projections, lanes, moved if projections.vehicles_first else None))
        finally:
            self._projections = None

    def _take_left_by_step(self) -> Moved | None:
        """`left_by_step`, once, if the road still holds the vehicles it moved, in the same order."""
        moved, self.left_by_step = self.left_by_step, None
        return moved if moved is not None and same_objects(moved.vehicles, self.vehicles) else None

    def _act_in(self, frame: TrafficFrame) -> None:
        """The act of one frame: split the IDM drivers from the other vehicles, decide (`_decide`),
        drive (`_drive`: every driver's steering and acceleration at once) and, when the frame's
        first rows are the road's vehicles, leave the step what it read and gave
        (`acted_for_step`)."""
        drivers, places, others = self._drivers_and_others()
        if not drivers:
            for vehicle in self.vehicles:
                vehicle.act()
            return
        self.driver_constants = KeptColumns.of(drivers, DRIVER_CONSTANTS, self.driver_constants)
        plan = Drivers(drivers, places, frame, self.driver_constants.rows)
        self._read_habits(plan)
        self._decide(plan, places, others)
        steering, acceleration = self._drive(plan)
        if frame.projections.vehicles_first:
            n = len(self.vehicles)
            self.acted_for_step = FrameActed(
                list(self.vehicles),
                frame.speed[:n],
                frame.heading[:n],
                frame.position[:n],
                np.array(places, dtype=int),
                steering,
                acceleration,
            )

    def _read_habits(self, plan: Drivers) -> None:
        """The drivers' habits (`plan.habits`, None if no driver has one), the ego's row and
        lane intent, the frame's clock, and this frame's s and speed of every row kept for the
        drivers that act on a delayed view."""
        kept = self.habit_columns
        if kept is None or not same_objects(kept[0], plan.drivers):
            kept = self.habit_columns = (list(plan.drivers), HabitColumns.of(plan.drivers))
        habits = kept[1]
        if not habits.any:
            return
        frame = plan.frame
        plan.habits, plan.frame_index = habits, self.acts - 1
        if (habits.blind or habits.yields) and self.ego is not None:
            plan.ego_row = self._ego_row(frame)
            plan.intent = self.ego_intent_lane
        if habits.delayed:
            rows = len(frame.s)
            if self.seen is None or self.seen.s.shape[2] != rows:
                self.seen = SeenPast(1, rows)
            self.seen.push(np.zeros(1, dtype=int), frame.s[None, :], frame.speed[None, :])

    def _ego_row(self, frame: TrafficFrame) -> int:
        """The ego's row in `frame`, -1 when it is not on the road."""
        if frame.projections.vehicles_first:
            return next((place for place, v in enumerate(self.vehicles) if v is self.ego), -1)
        return frame.row(self.ego) if any(v is self.ego for v in self.vehicles) else -1

    def _drivers_and_others(self) -> tuple[list[IDMVehicle], list[int], list[int]]:
        """The IDM drivers that act this frame (not crashed: stock's act returns at once for those),
        their places in the road's vehicles, and the places of the other vehicles."""
        drivers, places, others = [], [], []
        for place, vehicle in enumerate(self.vehicles):
            if type(vehicle) in IDM_DRIVERS and not vehicle.crashed:
                drivers.append(vehicle)
                places.append(place)
            else:
                others.append(place)
        return drivers, places, others

    def _decide(self, plan: Drivers, places: list[int], others: list[int]) -> None:
        """Every vehicle's discrete decisions, in the road's order as stock makes them (a driver's
        abort of a contested change reads the target lanes of those before it): the other vehicles
        act whole; the drivers due to decide take MOBIL's outcome, evaluated for all of them at once
        (`_mobil`: it reads positions and speeds, which no decision changes); those at their lane's
        end or whose change is due or runs decide as stock does (`_stock_decisions`); the rest
        decide nothing this frame. The drivers' target lanes are read again afterwards."""
        at_lane_end = plan.at_lane_end()
        decisions = self._mobil(plan, ~at_lane_end)
        may_change = plan.enable_lane_change & (plan.timer_due | ~plan.on_target)
        acting = set(decisions).union((at_lane_end | may_change).nonzero()[0].tolist())
        turns: list[tuple[int, int | None]] = [(place, None) for place in others]
        turns += [(places[k], k) for k in acting]
        retargeted = []
        for place, k in sorted(turns, key=itemgetter(0)):
            vehicle = self.vehicles[place]
            if k is None:
                vehicle.act()
            elif k in decisions:
                vehicle.timer = 0
                if decisions[k]:
                    vehicle.target_lane_index = decisions[k]
                    retargeted.append(k)
            elif self._stock_decisions(vehicle, bool(at_lane_end[k])):
                retargeted.append(k)
        plan.retarget(retargeted)

    def _stock_decisions(self, driver: IDMVehicle, at_lane_end: bool) -> bool:
        """`IDMVehicle.act`'s decisions for a driver MOBIL's batch left out: onto the next lane at
        its lane's end (`follow_road`), then `change_lane_policy` when its change is due or runs (a
        contested change is aborted there: `abort_contested_change`). Whether its target lane may
        have changed."""
        if at_lane_end:
            driver.follow_road()
        due = driver.LANE_CHANGE_DELAY < driver.timer
        if driver.enable_lane_change and driver.lane_index != driver.target_lane_index:
            abort_contested_change(driver, self.vehicles)
            return True
        if driver.enable_lane_change and due:
            driver.change_lane_policy()
            return True
        return at_lane_end

    def _mobil(self, plan: Drivers, free: np.ndarray) -> dict[int, LaneIndex | None]:
        """`change_lane_policy`'s outcome for the drivers due to decide (not those not `free`: they
        follow the road onto the next lane), keyed by their position in `plan.drivers`: the side
        lane MOBIL picks (the last one that passes, as stock overwrites), or None to keep the lane.
        Also evaluates every driver's IDM acceleration behind its own leader
        (`plan.own_acceleration`, and its free-road term `plan.own_free_road`), in the same array call."""
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
        own = plan.me, plan.own_front, plan.laws, plan.everyone
        if pairs:
            index = np.array([k for k, _ in pairs], dtype=int)
            sides = np.array([frame.lanes.row[side] for _, side in pairs], dtype=int)
            me = plan.me[index]
            reachable = frame.lanes.reachable(sides, frame.s[me], frame.r[sides, me])
            pairs = [pair for pair, keep in zip(pairs, reachable.tolist(), strict=True) if keep]
            index, sides, me = index[reachable], sides[reachable], me[reachable]
        if not pairs:
            plan.own_acceleration, plan.own_free_road = frame.idm_and_free_road(*own)
            return decisions
        new_front, new_rear = frame.neighbours(me, sides)
        if plan.habits is not None and plan.habits.blind:
            new_rear = unseen_ego(new_rear, plan.habits.blind_to_ego[index], plan.ego_row)
        own_front, own_rear = plan.own_front[index], plan.own_rear[index]
        blocks = 6
        evaluators = np.concatenate([index] * blocks + [plan.everyone])
        egos = np.concatenate([new_rear, new_rear, me, me, own_rear, own_rear, plan.me])
        leaders = np.concatenate([new_front, me, new_front, own_front, me, own_front, plan.own_front])
        laws = plan.laws
        a, free_road = frame.idm_and_free_road(egos, leaders, laws, evaluators)
        plan.own_acceleration, plan.own_free_road = a[blocks * len(me) :], free_road[blocks * len(me) :]
        accept = mobil_verdicts(
            a[: blocks * len(me)].reshape(blocks, -1),
            index,
            laws.politeness,
            laws.min_gain,
            laws.max_braking_imposed,
        )
        for (k, side), yes in zip(pairs, accept.tolist(), strict=True):
            if yes:
                decisions[k] = side
        return decisions

    def _drive(self, plan: Drivers) -> tuple[np.ndarray, np.ndarray]:
        """`IDMVehicle.act`'s steering [rad] and IDM acceleration [m/s^2] of every driver, after its
        decisions and habits (`delayed`, `yield_and_brake`): set as their actions, and returned."""
        frame, drivers, me = plan.frame, plan.drivers, plan.me
        lanes = frame.lanes
        heading, speed, target = frame.heading[me], frame.speed[me], plan.target
        changing = frame.lane[me] != target

        steering = steering_angles(frame.r[target, me], lanes.heading[target], heading, plan.length, speed)

        acceleration = plan.own_acceleration
        if plan.habits is not None and plan.habits.delayed:
            assert self.seen is not None
            delayed(plan, self.seen, acceleration)
        if changing.any():
            movers = changing.nonzero()[0]
            target_front, _ = frame.neighbours(me[movers], target[movers])
            on_target = frame.idm(me[movers], target_front, plan.laws, movers)
            acceleration[movers] = np.where(on_target < acceleration[movers], on_target, acceleration[movers])
        if plan.habits is not None:
            yield_and_brake(plan, acceleration)
        acceleration = clip(acceleration, IDMVehicle.ACC_MAX)
        for v, steer, accel in zip(drivers, steering, acceleration, strict=True):
            v.action = {"steering": steer, "acceleration": accel}
        return steering, acceleration

    def step(self, dt: float) -> None:
        """Stock `Road.step`: every vehicle moved over `dt` [s] (the kinematic ones at once, from what
        the act read and gave them when it read these very vehicles), then the collisions."""
        lanes = self._lane_table()
        if lanes is None:
            super().step(dt)
            return
        acted, self.acted_for_step = self.acted_for_step, None
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
        all_moved = moved if moved is not None and len(movers) == len(self.vehicles) else None
        self.moved = self.left_by_step = all_moved
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


DRIVER_CONSTANTS = attrgetter(
    "LENGTH",
    "DELTA",
    "DISTANCE_WANTED",
    "TIME_WANTED",
    "COMFORT_ACC_MAX",
    "COMFORT_ACC_MIN",
    "POLITENESS",
    "LANE_CHANGE_MIN_ACC_GAIN",
    "LANE_CHANGE_MAX_BRAKING_IMPOSED",
    "LANE_CHANGE_DELAY",
)
"""A driver's LENGTH [m] and its IDM and MOBIL parameters (`DriverLaws.of`'s arguments), under
highway-env's names: its class's, or its own when its population drew them (`stack.sim.drivers`)."""


class VectorHighwayEnv(ScenarioTraffic):
    """highway-v0 (with the scenarios' traffic, `stack.sim.traffic`) on a `VectorRoad`."""

    def _create_road(self) -> None:
        super()._create_road()
        VectorRoad.adopt(self.road)
