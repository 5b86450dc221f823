"""Many traffic worlds stepped together, with [worlds, vehicles] arrays as the state of record.

Each world is highway-v0 with the stack's traffic (`stack.sim.traffic`) and an ego driven by a given
actuation, the same world the `vector` backend drives alone through `HighwayAdapter`, bit for bit:
at reset highway-env spawns the world's road with the world's own generator (a seed, or the stream
the world's last reset left, as one env's `reset()` continues it), the arrays read it once, and from
then on a frame of every world is a fixed sequence of compiled kernels (`stack.sim.batched.kernels`,
the vector backend's `dynamics` and `frame.idm`) and numpy's transcendental calls and dot products
over all the worlds' vehicles at once, in highway-env's operation order:

- act: each world's lane coordinates and lane occupancy; every IDM driver's own-lane neighbours,
  its MOBIL candidates (when its timer is due) and abort candidates (while it changes lane); the
  IDM accelerations of all of them in one call; the decisions in road order per world (a driver
  reads the target lanes the ones before it just chose); the target-lane IDM of the drivers
  changing lane and the steering controller;
- step: `clip_actions` (and `TrafficVehicle`'s stop at a standstill), the kinematic bicycle,
  pending impacts, the lane-change timers, the closest lane; the collision candidates
  (`close_pair_rows`, a superset) go through highway-env's own `_is_colliding`, pair by pair in
  stock's order, which sets the impacts and crash flags.

The four facts this identity rests on are the vector backend's (`stack.sim.vector.road`). Worlds
whose episode ended (the ego crashed, or the duration is reached) are reset at their next `step`,
which returns their first frame instead of stepping them (gymnasium's next-step autoreset); the
other worlds step on, untouched. `road(world)` builds highway-env's objects on request."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import gymnasium as gym
import numpy as np
from highway_env import utils
from highway_env.envs.common.action import ContinuousAction
from highway_env.road.lane import StraightLane
from highway_env.road.road import RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import RoadObject

from stack.sim.batched.arrays import (
    LANE_COLUMNS,
    PLAIN,
    TRAFFIC,
    VEHICLE_COLUMNS,
    SpawnedWorld,
    read_world,
    road_of,
)
from stack.sim.batched.kernels import (
    closest_lane_rows,
    collision_candidates,
    decide,
    lane_frames,
    lane_neighbours,
    plan_decisions,
)
from stack.sim.envs import HIGHWAY
from stack.sim.fast_road import BROAD_PHASE_MARGIN, NEIGHBOUR_MARGIN
from stack.sim.highway import MAX_ACCELERATION, MAX_STEERING, env_config
from stack.sim.settings import HighwayConfig
from stack.sim.traffic import ScenarioTraffic
from stack.sim.vector.dynamics import bicycle_step, clipped_actions, steering_angles
from stack.sim.vector.frame import BRAKING_TERM, IdmRows
from stack.sim.vector.kernels import SEPARATION_MARGIN
from stack.sim.vector.lanes import LaneTable, clip


@dataclass(frozen=True, eq=False)
class Ended:
    """Per world, after a step: whether its episode ended by the ego's crash (`terminated`) or
    its duration (`truncated`); such a world is reset at its next step."""

    terminated: np.ndarray
    truncated: np.ndarray


class TrafficBatch:
    """N worlds of one highway config (`HighwayConfig`, kinematic ego), stepped together."""

    def __init__(self, highway: HighwayConfig, worlds: int) -> None:
        if worlds < 1:
            raise ValueError(f"a batch needs at least one world, got {worlds}")
        if highway.road != "highway":
            raise ValueError(
                f"batched traffic runs the highway road, not {highway.road!r} (a curved exit lane)"
            )
        self.highway = highway
        self.worlds = worlds
        self._spawner = gym.make(HIGHWAY, config=env_config(highway), disable_env_checker=True)
        self._env = cast(ScenarioTraffic, self._spawner.unwrapped)
        config = self._env.config
        self.dt = 1 / config["simulation_frequency"]
        self._time_step = 1 / config["policy_frequency"]
        self._duration = config["duration"]
        self._offroad_terminal = bool(config["offroad_terminal"])
        self._rngs: list[np.random.Generator | None] = [None] * worlds
        self._lane_tables: list[LaneTable | None] = [None] * worlds
        self._networks: list[RoadNetwork | None] = [None] * worlds
        self.vehicles, self.lanes = 0, 0
        self.columns: dict[str, np.ndarray] = {}
        self.lane_columns: dict[str, np.ndarray] = {}
        self._allocate(1, 1)
        self.count = np.zeros(worlds, dtype=np.int64)
        """Vehicles in each world (its first rows)."""
        self.ego = np.zeros(worlds, dtype=np.int64)
        """The ego's row in each world."""
        self.time = np.zeros(worlds)
        """Each world's episode time [s], as the env counts it."""
        self.ended = Ended(np.zeros(worlds, dtype=bool), np.zeros(worlds, dtype=bool))
        self._pending_reset = np.zeros(worlds, dtype=bool)

    def close(self) -> None:
        self._spawner.close()

    def __getattr__(self, name: str) -> np.ndarray:
        """A vehicle column (worlds, vehicles) or lane column (worlds, lanes) by name."""
        for table in ("columns", "lane_columns"):
            held = self.__dict__.get(table, {})
            if name in held:
                return held[name]
        raise AttributeError(name)

    def _allocate(self, vehicles: int, lanes: int) -> None:
        """Room for `vehicles` a world and `lanes` lanes, keeping what the arrays hold."""
        vehicles, lanes = max(vehicles, self.vehicles), max(lanes, self.lanes)
        if (vehicles, lanes) == (self.vehicles, self.lanes):
            return
        for table, spec, size in (
            (self.columns, VEHICLE_COLUMNS, vehicles),
            (self.lane_columns, LANE_COLUMNS, lanes),
        ):
            for name, (dtype, empty) in spec.items():
                grown: np.ndarray = np.full((self.worlds, size), empty, dtype=dtype)
                old = table.get(name)
                if old is not None:
                    grown[:, : old.shape[1]] = old
                table[name] = grown
        for name, shape in (("start", (lanes, 2)), ("lateral", (lanes, 2))):
            grown = np.zeros((self.worlds, *shape))
            old = self.lane_columns.get(name)
            if old is not None:
                grown[:, : old.shape[1]] = old
            self.lane_columns[name] = grown
        if "direction" not in self.lane_columns:
            self.lane_columns["direction"] = np.zeros((self.worlds, 2))
            self.lane_columns["lane_count"] = np.zeros(self.worlds, dtype=np.int64)
        self.vehicles, self.lanes = vehicles, lanes

    def reset(self, seeds: Sequence[int]) -> None:
        """Reset every world, world k with `seeds[k]`."""
        if len(seeds) != self.worlds:
            raise ValueError(f"one seed per world: {self.worlds} worlds, {len(seeds)} seeds")
        for world, seed in enumerate(seeds):
            self.reset_world(world, seed)

    def reset_world(self, world: int, seed: int | None = None) -> None:
        """Spawn world `world` anew: with `seed`, or (None) with the generator its last reset left."""
        env = self._env
        if seed is None:
            rng = self._rngs[world]
            if rng is None:
                raise ValueError(f"world {world} has no generator yet: reset it with a seed first")
            env._np_random = rng
        self._spawner.reset(seed=seed)
        self._rngs[world] = env.np_random
        if type(env.vehicle) is not Vehicle:
            raise ValueError("batched traffic drives a kinematic ego (plant: kinematic)")
        self._load(world, read_world(env.road, env.vehicle))
        self.time[world] = env.time
        self.ended.terminated[world] = self.ended.truncated[world] = False
        self._pending_reset[world] = False

    def _load(self, world: int, spawned: SpawnedWorld) -> None:
        n, lanes = len(spawned.columns["x"]), len(spawned.lanes.indices)
        self._allocate(n, lanes)
        for name, (_, empty) in VEHICLE_COLUMNS.items():
            self.columns[name][world] = empty
            self.columns[name][world, :n] = spawned.columns[name]
        table = spawned.lanes
        lane_values = {
            "lane_length": table.length,
            "half_width": table.half_width,
            "lane_heading": table.heading,
            "speed_limit": table.speed_limit,
            "forbidden": table.forbidden,
            "start": table.start,
            "lateral": table.lateral,
        }
        for name, values in lane_values.items():
            column = self.lane_columns[name]
            column[world] = LANE_COLUMNS[name][1] if name in LANE_COLUMNS else 0.0
            column[world, :lanes] = values
        self.lane_columns["direction"][world] = table.direction
        self.lane_columns["lane_count"][world] = lanes
        self.count[world], self.ego[world] = n, spawned.ego
        self._lane_tables[world], self._networks[world] = table, spawned.network

    def step(self, acceleration: np.ndarray, steering: np.ndarray) -> Ended:
        """One frame of every world, the ego of world k actuated with `acceleration[k]` [m/s^2] and
        `steering[k]` [rad] (through `ContinuousAction`'s normalised range, as `HighwayAdapter`
        applies an `Actuation`: +-5 m/s^2, +-pi/4 rad at most). Worlds that ended at the last step
        are reset instead (their actuation is ignored)."""
        resetting = self._pending_reset.nonzero()[0]
        for world in resetting.tolist():
            self.reset_world(world)
        stepping = ~self._pending_reset
        stepping[resetting] = False
        active = np.where(stepping, self.count, 0)
        self.time[stepping] += self._time_step
        ego_rows = self._flat_rows(stepping.nonzero()[0], self.ego[stepping])
        self._drive_egos(ego_rows, acceleration[stepping], steering[stepping])
        self._act(active)
        self._move(active)
        ego_crashed = self.crashed.reshape(-1)[self._flat_rows(np.arange(self.worlds), self.ego)]
        terminated = stepping & (ego_crashed | (self._offroad_terminal & ~self._egos_on_road()))
        truncated = stepping & (self.time >= self._duration)
        self.ended = Ended(terminated, truncated)
        self._pending_reset = terminated | truncated
        return self.ended

    def _flat_rows(self, worlds: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return np.asarray(worlds * self.vehicles + rows, dtype=np.int64)

    def _drive_egos(self, rows: np.ndarray, acceleration: np.ndarray, steering: np.ndarray) -> None:
        """`HighwayAdapter.step`'s actuation on the egos: normalised by `to_env_action`, then mapped
        back by `ContinuousAction` (the same float operations)."""
        normalised_acceleration = np.minimum(np.maximum(acceleration / MAX_ACCELERATION, -1.0), 1.0)
        normalised_steering = np.minimum(np.maximum(steering / MAX_STEERING, -1.0), 1.0)
        self.acceleration.reshape(-1)[rows] = utils.lmap(
            np.clip(normalised_acceleration, -1, 1), [-1, 1], ContinuousAction.ACCELERATION_RANGE
        )
        self.steering.reshape(-1)[rows] = utils.lmap(
            np.clip(normalised_steering, -1, 1), [-1, 1], ContinuousAction.STEERING_RANGE
        )

    def _lane_args(self) -> tuple[np.ndarray, ...]:
        lanes = self.lane_columns
        return lanes["lane_count"], lanes["start"], lanes["direction"], lanes["lateral"]

    def _act(self, active: np.ndarray) -> None:
        """`Road.act()` of every active world: the IDM drivers' decisions, steering and acceleration."""
        flat = {name: column.reshape(-1) for name, column in self.columns.items()}
        lanes = self.lane_columns
        lane_count, start, direction, lateral = self._lane_args()
        s, r, on, on_count = lane_frames(
            active,
            self.x,
            self.y,
            lane_count,
            start,
            direction,
            lateral,
            lanes["lane_length"],
            lanes["half_width"],
            StraightLane.VEHICLE_LENGTH,
            NEIGHBOUR_MARGIN,
        )
        in_world = np.arange(self.vehicles)[None, :] < active[:, None]
        kind, crashed = flat["kind"], flat["crashed"]
        drivers = np.flatnonzero(in_world.reshape(-1) & (kind != PLAIN) & ~crashed)
        if len(drivers) == 0:
            return
        world_of = np.repeat(np.arange(self.worlds), self.vehicles)
        heading, speed = flat["heading"], flat["speed"]
        direction_of = np.empty((len(heading), 2))
        direction_of[:, 0], direction_of[:, 1] = np.cos(heading), np.sin(heading)
        kinematics = IdmRows(
            is_vehicle=np.ones(len(speed), dtype=bool),
            speed=speed,
            target_speed=flat["target_speed"],
            speed_limit=lanes["speed_limit"][world_of, flat["lane"]],
            s=s.reshape(-1),
            velocity=speed[:, None] * direction_of,
            direction=direction_of,
        )
        lane, target, timer = flat["lane"], flat["target_lane"], flat["timer"]
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
                IDMVehicle.LANE_CHANGE_DELAY,
                IDMVehicle.TIME_WANTED,
                BRAKING_TERM,
                StraightLane.VEHICLE_LENGTH,
            )
        )
        me = drivers[side_driver]
        mover_rear, mover_front = own_rear[side_driver], own_front[side_driver]
        egos = np.concatenate([side_rear, side_rear, me, me, mover_rear, mover_rear, drivers])
        leaders = np.concatenate([side_front, me, side_front, mover_front, me, mover_front, own_front])
        evaluators = np.concatenate([me] * 6 + [drivers])
        a = kinematics.idm(egos, leaders, flat["delta"][evaluators], flat["distance_wanted"][evaluators])
        blocks = 6 * len(me)
        side_accelerations, own_acceleration = a[:blocks].reshape(6, -1), a[blocks:]
        changer = drivers[pair_driver]
        closing = np.vecdot(
            kinematics.velocity[changer] - kinematics.velocity[pair_other], direction_of[changer]
        )
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
            IDMVehicle.LANE_CHANGE_DELAY,
            IDMVehicle.TIME_WANTED,
            BRAKING_TERM,
            IDMVehicle.POLITENESS,
            IDMVehicle.LANE_CHANGE_MIN_ACC_GAIN,
            IDMVehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED,
        )
        goal = target[drivers]
        changing = (lane[drivers] != goal).nonzero()[0]
        acceleration = own_acceleration
        if len(changing):
            movers = drivers[changing]
            target_front, _ = lane_neighbours(movers, goal[changing], s, on, on_count)
            on_target = kinematics.idm(
                movers, target_front, flat["delta"][movers], flat["distance_wanted"][movers]
            )
            acceleration[changing] = np.where(
                on_target < acceleration[changing], on_target, acceleration[changing]
            )
        world, row = drivers // self.vehicles, drivers % self.vehicles
        flat["steering"][drivers] = steering_angles(
            r[world, goal, row],
            lanes["lane_heading"][world, goal],
            heading[drivers],
            flat["length"][drivers],
            speed[drivers],
        )
        flat["acceleration"][drivers] = clip(acceleration, IDMVehicle.ACC_MAX)

    def _move(self, active: np.ndarray) -> None:
        """`Road.step(dt)` of every active world: the vehicles' steps, then the collisions."""
        flat = {name: column.reshape(-1) for name, column in self.columns.items()}
        in_world = np.arange(self.vehicles)[None, :] < active[:, None]
        rows = np.flatnonzero(in_world.reshape(-1))
        if len(rows) == 0:
            return
        dt = self.dt
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
        lanes = self.lane_columns
        lane_count, start, direction, lateral = self._lane_args()
        closest = closest_lane_rows(
            active,
            self.x,
            self.y,
            self.heading,
            lane_count,
            start,
            direction,
            lateral,
            lanes["lane_length"],
            lanes["lane_heading"],
        )
        self.columns["lane"][...] = np.where(closest >= 0, closest, self.lane)
        plain = self.kind == PLAIN
        self.target_lane[plain] = self.lane[plain]
        self._collide(active)

    def _collide(self, active: np.ndarray) -> None:
        """highway-env's collision test on the candidate pairs, in stock's order (world by world,
        i < j): impacts for the next step, crash flags now."""
        candidates = collision_candidates(
            active,
            self.x,
            self.y,
            self.heading,
            self.speed,
            self.length,
            self.width,
            self.diagonal,
            self.lane_columns["direction"],
            self.dt,
            BROAD_PHASE_MARGIN,
            SEPARATION_MARGIN,
        )
        for world, i, j in candidates.tolist():
            first, second = self._body(world, i), self._body(world, j)
            intersecting, will_intersect, transition = first._is_colliding(second, self.dt)
            if will_intersect:
                self._set_impact(world, i, transition / 2)
                self._set_impact(world, j, -transition / 2)
            if intersecting:
                self.crashed[world, i] = self.crashed[world, j] = True

    def _body(self, world: int, row: int) -> _Body:
        columns = self.columns
        return _Body(
            np.array([columns["x"][world, row], columns["y"][world, row]]),
            float(columns["heading"][world, row]),
            float(columns["speed"][world, row]),
            float(columns["length"][world, row]),
            float(columns["width"][world, row]),
            float(columns["diagonal"][world, row]),
        )

    def _set_impact(self, world: int, row: int, impact: np.ndarray) -> None:
        self.impact_x[world, row], self.impact_y[world, row] = impact
        self.impacted[world, row] = True

    def _egos_on_road(self) -> np.ndarray:
        """Whether each world's ego is on its lane (`RoadObject.on_road`)."""
        worlds = np.arange(self.worlds)
        lane = self.lane[worlds, self.ego]
        lanes = self.lane_columns
        delta_x = self.x[worlds, self.ego] - lanes["start"][worlds, lane, 0]
        delta_y = self.y[worlds, self.ego] - lanes["start"][worlds, lane, 1]
        s = delta_x * lanes["direction"][:, 0] + delta_y * lanes["direction"][:, 1]
        r = delta_x * lanes["lateral"][worlds, lane, 0] + delta_y * lanes["lateral"][worlds, lane, 1]
        length = lanes["lane_length"][worlds, lane]
        vehicle_length = StraightLane.VEHICLE_LENGTH
        return (
            (np.abs(r) <= lanes["half_width"][worlds, lane])
            & (-vehicle_length <= s)
            & (s < length + vehicle_length)
        )

    def road(self, world: int) -> tuple[list[Vehicle], Vehicle]:
        """highway-env objects of world `world` as it stands: its vehicles on a new `Road` of its
        lanes (road order), and its ego (for rendering, video, a user reading the road)."""
        table, network, rng = self._lane_tables[world], self._networks[world], self._rngs[world]
        if table is None or network is None or rng is None:
            raise ValueError(f"world {world} has not been reset")
        n = int(self.count[world])
        columns = {name: column[world, :n] for name, column in self.columns.items()}
        vehicles = road_of(columns, table, network, rng)
        return vehicles, vehicles[int(self.ego[world])]


class _Body(RoadObject):
    """A vehicle's footprint as highway-env's collision test reads it (`RoadObject._is_colliding`:
    position, heading, speed, size, diagonal), without a road."""

    def __init__(
        self, position: np.ndarray, heading: float, speed: float, length: float, width: float, diagonal: float
    ) -> None:
        self.position, self.heading, self.speed = position, heading, speed
        self.LENGTH, self.WIDTH, self.diagonal = length, width, diagonal
