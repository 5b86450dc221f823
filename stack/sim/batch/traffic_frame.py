"""One frame of a batch of traffic worlds over its arrays (`BatchArrays`): `act` (highway-env's
`Road.act()`: the IDM drivers' decisions, steering and acceleration), `move` (`Road.step(dt)`: the
vehicles' steps, then `collide`). Compiled kernels (`stack.sim.batch.traffic_kernels`, the vector backend's
`dynamics`) around numpy's transcendental calls and dot products, in highway-env's operation order;
only the worlds with vehicles in `active` (a count per world, 0 for a world left as it is) move."""

from __future__ import annotations

from functools import cache, lru_cache

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.objects import RoadObject

from stack.sim.batch.arrays import DRIVER_LAWS, PLAIN, TRAFFIC, BatchArrays
from stack.sim.batch.segment_kernels import crossing_drivers, segments_of
from stack.sim.batch.traffic_kernels import (
    closest_lane_rows,
    collision_candidates,
    decide,
    lane_frames,
    lane_neighbours,
    plan_decisions,
)
from stack.sim.fast_road import BROAD_PHASE_MARGIN, NEIGHBOUR_MARGIN
from stack.sim.vector.dynamics import bicycle_step, clipped_actions, steering_angles
from stack.sim.vector.geometry_kernels import SEPARATION_MARGIN
from stack.sim.vector.habits import (
    delayed_accelerations,
    sudden_accelerations,
    unseen_ego,
    yielders,
    yielding,
)
from stack.sim.vector.lanes import clip
from stack.sim.vector.road_frame import DriverLaws, IdmRows


def lane_frame(
    arrays: BatchArrays, active: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`lane_frames` of the worlds' vehicles as they stand: s (W, V) and r (W, L, V) [m], the
    vehicles highway-env's neighbour search counts on each lane (W, L, V) and how many (W, L)."""
    lanes = arrays.lane_columns
    lane_count, start, direction, lateral = arrays.lane_args()
    return lane_frames(
        active,
        arrays.x,
        arrays.y,
        lane_count,
        start,
        direction,
        lateral,
        lanes["lane_length"],
        lanes["half_width"],
        StraightLane.VEHICLE_LENGTH,
        NEIGHBOUR_MARGIN,
    )


def in_worlds(arrays: BatchArrays, active: np.ndarray) -> np.ndarray:
    """(W * V,) bool: each row of the flat arrays holds a vehicle of an active world (the first
    `active[w]` rows of world w)."""
    in_world: np.ndarray = (np.arange(arrays.vehicles)[None, :] < active[:, None]).reshape(-1)
    return in_world


@cache
def _world_rows(worlds: int, vehicles: int) -> tuple[np.ndarray, np.ndarray]:
    """The world of each row of flat arrays of `worlds` x `vehicles`, and an all-true flag a row
    (never written: shared by every frame of that shape)."""
    return np.repeat(np.arange(worlds), vehicles), np.ones(worlds * vehicles, dtype=bool)


def act(arrays: BatchArrays, active: np.ndarray, in_world: np.ndarray) -> None:
    """`Road.act()` of every active world (`in_world`, `in_worlds`): the IDM drivers' decisions,
    steering and acceleration."""
    flat = arrays.flat
    lanes = arrays.lane_columns
    lane_count = lanes["lane_count"]
    arrays.acts[active > 0] += 1
    s, r, on, on_count = lane_frame(arrays, active)
    kind, crashed = flat["kind"], flat["crashed"]
    drivers = np.flatnonzero(in_world & (kind != PLAIN) & ~crashed)
    if len(drivers) == 0:
        return
    if arrays.seen is not None:
        acting = np.flatnonzero(active > 0)
        arrays.seen.push(acting, s, arrays.speed)
    world_of, is_vehicle = _world_rows(arrays.worlds, arrays.vehicles)
    heading, speed = flat["heading"], flat["speed"]
    direction_of = np.empty((len(heading), 2))
    direction_of[:, 0], direction_of[:, 1] = np.cos(heading), np.sin(heading)
    kinematics = IdmRows(
        is_vehicle=is_vehicle,
        speed=speed,
        target_speed=flat["target_speed"],
        speed_limit=lanes["speed_limit"][world_of, flat["lane"]],
        s=s.reshape(-1),
        velocity=speed[:, None] * direction_of,
        direction=direction_of,
    )
    lane, target, timer = flat["lane"], flat["target_lane"], flat["timer"]
    laws = DriverLaws.of(*(flat[name] for name in DRIVER_LAWS))
    own_front, own_rear, side_driver, side_lane, side_front, side_rear, pair_driver, pair_other = (
        plan_decisions(
            drivers,
            lane,
            target,
            speed,
            timer,
            flat["enable_lane_change"],
            kind != PLAIN,
            flat["distance_wanted"],
            active,
            s,
            r,
            on,
            on_count,
            lane_count,
            lanes["lane_length"],
            lanes["half_width"],
            lanes["forbidden"],
            laws.lane_change_delay,
            laws.time_wanted,
            laws.braking_term,
            *arrays.segment_args(),
            StraightLane.VEHICLE_LENGTH,
        )
    )
    me = drivers[side_driver]
    if arrays.habits:
        egos_of = np.arange(arrays.worlds) * arrays.vehicles + arrays.ego
        side_rear = unseen_ego(side_rear, flat["blind_to_ego"][me], egos_of[me // arrays.vehicles])
    mover_rear, mover_front = own_rear[side_driver], own_front[side_driver]
    egos = np.concatenate([side_rear, side_rear, me, me, mover_rear, mover_rear, drivers])
    leaders = np.concatenate([side_front, me, side_front, mover_front, me, mover_front, own_front])
    evaluators = np.concatenate([me] * 6 + [drivers])
    a, free_road = kinematics.idm_and_free_road(egos, leaders, laws, evaluators)
    blocks = 6 * len(me)
    side_accelerations, own_acceleration = a[:blocks].reshape(6, -1), a[blocks:]
    changer = drivers[pair_driver]
    closing = np.vecdot(kinematics.velocity[changer] - kinematics.velocity[pair_other], direction_of[changer])
    decide(
        drivers,
        lane,
        target,
        timer,
        flat["enable_lane_change"],
        speed,
        kinematics.s,
        flat["distance_wanted"],
        side_driver,
        side_lane,
        side_accelerations,
        pair_driver,
        pair_other,
        closing,
        laws.lane_change_delay,
        laws.time_wanted,
        laws.braking_term,
        laws.politeness,
        laws.min_gain,
        laws.max_braking_imposed,
    )
    goal = target[drivers]
    changing = (lane[drivers] != goal).nonzero()[0]
    acceleration = own_acceleration
    if arrays.seen is not None:
        _delayed(arrays, flat, kinematics, laws, drivers, own_front, free_road[blocks:], acceleration)
    segment_start, segment_length, segment_count = arrays.segment_args()
    if len(changing):
        movers = drivers[changing]
        own_segment = segments_of(movers, s, segment_start, segment_length, segment_count)
        target_front, _ = lane_neighbours(
            movers, goal[changing], s, on, on_count, own_segment, segment_start, segment_length,
            StraightLane.VEHICLE_LENGTH,
        )  # fmt: skip
        on_target = kinematics.idm(movers, target_front, laws, movers)
        acceleration[changing] = np.where(
            on_target < acceleration[changing], on_target, acceleration[changing]
        )
    if arrays.segmented:
        _crossing(arrays, kinematics, laws, drivers, s, on, on_count, acceleration)
    if arrays.habits:
        _yield_and_brake(arrays, flat, kinematics, laws, drivers, acceleration)
    world, row = drivers // arrays.vehicles, drivers % arrays.vehicles
    flat["steering"][drivers] = steering_angles(
        r[world, goal, row],
        lanes["lane_heading"][world, goal],
        heading[drivers],
        flat["length"][drivers],
        speed[drivers],
    )
    flat["acceleration"][drivers] = clip(acceleration, IDMVehicle.ACC_MAX)


def _crossing(
    arrays: BatchArrays,
    kinematics: IdmRows,
    laws: DriverLaws,
    drivers: np.ndarray,
    s: np.ndarray,
    on: np.ndarray,
    on_count: np.ndarray,
    acceleration: np.ndarray,
) -> None:
    """The drivers whose route already targets the next segment's lane (`crossing_drivers`): the
    lower of their acceleration and the IDM's behind their leader there, in place."""
    segment_start, segment_length, segment_count = arrays.segment_args()
    crossing, following = crossing_drivers(
        drivers, s, segment_start, segment_length, segment_count, StraightLane.VEHICLE_LENGTH
    )
    if len(crossing) == 0:
        return
    movers = drivers[crossing]
    front, _ = lane_neighbours(
        movers, arrays.flat["target_lane"][movers], s, on, on_count, following, segment_start,
        segment_length, StraightLane.VEHICLE_LENGTH,
    )  # fmt: skip
    ahead = kinematics.idm(movers, front, laws, movers)
    acceleration[crossing] = np.where(ahead < acceleration[crossing], ahead, acceleration[crossing])


def _delayed(
    arrays: BatchArrays,
    flat: dict[str, np.ndarray],
    kinematics: IdmRows,
    laws: DriverLaws,
    drivers: np.ndarray,
    own_front: np.ndarray,
    free_road: np.ndarray,
    acceleration: np.ndarray,
) -> None:
    """The own-lane IDM of the drivers that act on a delayed view, in place
    (`delayed_accelerations` over the worlds' `seen` past, from the drivers' `free_road` terms
    [m/s^2]), as the vector road computes it."""
    seen = arrays.seen
    assert seen is not None
    delayed_accelerations(
        acceleration, drivers, drivers, own_front, arrays.vehicles, flat["delay_frames"], seen.s, seen.speed,
        seen.pushed, free_road, kinematics.speed, laws.a_max, laws.distance_wanted, laws.time_wanted,
        laws.braking_term,
    )  # fmt: skip


def _yield_and_brake(
    arrays: BatchArrays,
    flat: dict[str, np.ndarray],
    kinematics: IdmRows,
    laws: DriverLaws,
    drivers: np.ndarray,
    acceleration: np.ndarray,
) -> None:
    """The yielding drivers behind their ego's lane change (`yielders`, `yielding`) and the sudden
    brakings (`sudden_accelerations`), in place, as the vector road computes them."""
    world = drivers // arrays.vehicles
    if flat["yields_to_ego"].any():
        _yield(arrays, flat, kinematics, laws, drivers, world, flat["yields_to_ego"][drivers], acceleration)
    if flat["sudden_braking_chance"].any():
        sudden_accelerations(
            acceleration, drivers, arrays.acts[world] - 1, flat["habit_key"], flat["sudden_braking_chance"],
            flat["sudden_braking_frames"], flat["sudden_braking_mps2"],
        )  # fmt: skip


def _yield(
    arrays: BatchArrays,
    flat: dict[str, np.ndarray],
    kinematics: IdmRows,
    laws: DriverLaws,
    drivers: np.ndarray,
    world: np.ndarray,
    yields: np.ndarray,
    acceleration: np.ndarray,
) -> None:
    """The yielding drivers behind their ego's lane change, in place (`yielders`, `yielding`)."""
    egos = (np.arange(arrays.worlds) * arrays.vehicles + arrays.ego)[world]
    yield_now = yielders(
        yields, flat["lane"][drivers], arrays.intent[world], kinematics.s[drivers], kinematics.s[egos]
    ).nonzero()[0]
    if len(yield_now):
        yielders_rows = drivers[yield_now]
        behind_ego = kinematics.idm(yielders_rows, egos[yield_now], laws, yielders_rows)
        acceleration[yield_now] = yielding(
            acceleration[yield_now], behind_ego, flat["comfort_acc_min"][yielders_rows]
        )


def move(arrays: BatchArrays, active: np.ndarray, in_world: np.ndarray, dt: float) -> None:
    """`Road.step(dt)` of every active world (`in_world`, `in_worlds`): the vehicles' steps, then
    the collisions."""
    flat = arrays.flat
    rows = np.flatnonzero(in_world)
    if len(rows) == 0:
        return
    speed, crashed = flat["speed"][rows], flat["crashed"][rows]
    steering, acceleration = clipped_actions(
        speed,
        flat["max_speed"][rows],
        flat["min_speed"][rows],
        flat["steering"][rows],
        flat["acceleration"][rows],
        crashed,
        flat["kind"][rows] == TRAFFIC,
        dt,
    )
    flat["steering"][rows], flat["acceleration"][rows] = steering, acceleration
    x, y = flat["x"][rows], flat["y"][rows]
    heading, speed = bicycle_step(
        x, y, flat["heading"][rows], speed, steering, acceleration, flat["length"][rows], dt
    )
    impacted = flat["impacted"][rows]
    if impacted.any():
        x[impacted] += flat["impact_x"][rows][impacted]
        y[impacted] += flat["impact_y"][rows][impacted]
        flat["crashed"][rows[impacted]] = True
        flat["impacted"][rows[impacted]] = False
    flat["x"][rows], flat["y"][rows] = x, y
    flat["heading"][rows], flat["speed"][rows] = heading, speed
    timed = rows[flat["kind"][rows] != PLAIN]
    flat["timer"][timed] += dt
    lanes = arrays.lane_columns
    lane_count, start, direction, lateral = arrays.lane_args()
    closest = closest_lane_rows(
        active,
        arrays.x,
        arrays.y,
        arrays.heading,
        lane_count,
        start,
        direction,
        lateral,
        lanes["lane_length"],
        lanes["lane_heading"],
    )
    arrays.columns["lane"][...] = np.where(closest >= 0, closest, arrays.lane)
    plain = arrays.kind == PLAIN
    arrays.target_lane[plain] = arrays.lane[plain]
    collide(arrays, active, dt)


def collide(arrays: BatchArrays, active: np.ndarray, dt: float) -> None:
    """highway-env's collision test on the candidate pairs, in stock's order (world by world,
    i < j): impacts for the next step, crash flags now."""
    candidates = collision_candidates(
        active, arrays.x, arrays.y, arrays.heading, arrays.speed, arrays.length, arrays.width,
        arrays.diagonal, arrays.lane_columns["direction"], dt, BROAD_PHASE_MARGIN, SEPARATION_MARGIN,
    )  # fmt: skip
    for world, i, j in candidates.tolist():
        intersecting, will_intersect, transition = _tested(
            _footprint(arrays, world, i), _footprint(arrays, world, j), dt
        )
        if will_intersect:
            _set_impact(arrays, world, i, transition / 2)
            _set_impact(arrays, world, j, -transition / 2)
        if intersecting:
            arrays.crashed[world, i] = arrays.crashed[world, j] = True


def _footprint(arrays: BatchArrays, world: int, row: int) -> tuple[float, ...]:
    """What highway-env's collision test reads of the vehicle in `row` of `world`: x, y [m],
    heading [rad], speed [m/s], length, width and diagonal [m]."""
    return tuple(
        float(arrays.columns[name][world, row])
        for name in ("x", "y", "heading", "speed", "length", "width", "diagonal")
    )


@lru_cache(maxsize=4096)
def _tested(first: tuple[float, ...], second: tuple[float, ...], dt: float) -> tuple[bool, bool, np.ndarray]:
    """`RoadObject._is_colliding` of two `_footprint`s over `dt` [s], remembered: a function of
    them alone, and wrecks that stand touching are tested with the same values frame after frame
    (the test in Python is most of what a population whose drivers crash costs a batch)."""
    body, other = (Body(np.array(f[:2]), *f[2:]) for f in (first, second))
    return body._is_colliding(other, dt)


def _set_impact(arrays: BatchArrays, world: int, row: int, impact: np.ndarray) -> None:
    arrays.impact_x[world, row], arrays.impact_y[world, row] = impact
    arrays.impacted[world, row] = True


class Body(RoadObject):
    """A vehicle's footprint as highway-env's collision test reads it (`RoadObject._is_colliding`:
    position, heading, speed, size, diagonal), without a road."""

    def __init__(
        self, position: np.ndarray, heading: float, speed: float, length: float, width: float, diagonal: float
    ) -> None:
        self.position, self.heading, self.speed = position, heading, speed
        self.LENGTH, self.WIDTH, self.diagonal = length, width, diagonal
