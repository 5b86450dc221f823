"""The highway-env adapter: the only module that reaches into `env.unwrapped`.

It creates highway-v0 with `ContinuousAction` and `policy_frequency == simulation_frequency`, so one
`step` is one physics frame and one control tick, and turns the road into a `WorldState` snapshot.
"""

from __future__ import annotations

import math
import os
import weakref
from typing import cast

if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":  # highway-env skips drawing under "dummy"
    os.environ["SDL_VIDEODRIVER"] = "offscreen"
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import gymnasium as gym
import highway_env  # noqa: F401  (registers highway-v0)
import numpy as np
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.envs.common.action import ContinuousAction
from highway_env.road.lane import AbstractLane, StraightLane
from highway_env.road.road import Road
from highway_env.vehicle.dynamics import BicycleVehicle
from highway_env.vehicle.kinematics import Vehicle
from numba.extending import register_jitable

from records import BACKENDS, Actuation, Backend, PlantName, RoadName, WorldState, unknown_name
from stack.settings.world import HighwayConfig
from stack.sim.envs import EXIT, FAST_EXIT, FAST_HIGHWAY, HIGHWAY, VECTOR_HIGHWAY
from stack.sim.plant import stabilised
from stack.sim.traffic import TRAFFIC_VEHICLE
from stack.sim.vector.motion import Moved, columns

ENV_IDS: dict[RoadName, dict[Backend, str]] = {
    "highway": {"vector": VECTOR_HIGHWAY, "fast": FAST_HIGHWAY, "stock": HIGHWAY},
    "exit": {"vector": FAST_EXIT, "fast": FAST_EXIT, "stock": EXIT},
}
"""Simulation backends: the gymnasium id each one runs (exit-v0's curved exit lane is outside what
`VectorRoad` vectorises, so its `vector` is the fast road)."""

MAX_ACCELERATION = ContinuousAction.ACCELERATION_RANGE[1]
"""Acceleration that ContinuousAction maps to +1 [m/s^2]."""
MAX_STEERING = ContinuousAction.STEERING_RANGE[1]
"""Steering angle that ContinuousAction maps to +1 [rad]."""


def env_config(highway: HighwayConfig, plant: PlantName = "kinematic") -> dict:
    """The highway-env config for a closed-loop run: continuous action (on highway-env's dynamic
    bicycle for the `dynamic` plant), one frame per step, traffic that stops instead of reversing
    and starts feasible (the stack's world; the gym ids alone are highway-v0's)."""
    return {
        **highway.model_dump(mode="json", exclude={"road"}),
        "other_vehicles_type": TRAFFIC_VEHICLE,
        "feasible_spawns": True,
        "policy_frequency": highway.simulation_frequency,
        "action": {"type": "ContinuousAction", "dynamical": plant == "dynamic"},
        # The stack reads the road itself; the cheapest observation keeps highway-env's work minimal.
        "observation": {"type": "AttributesObservation", "attributes": ["time"]},
    }


def to_env_action(actuation: Actuation) -> np.ndarray:
    """Physical [acceleration m/s^2, steering rad] -> ContinuousAction's normalised [-1, 1]^2."""
    acceleration = unit_command(actuation.acceleration, MAX_ACCELERATION)
    return np.array([acceleration, unit_command(actuation.steering, MAX_STEERING)])


@register_jitable
def unit_command(value: float, limit: float) -> float:
    """A command `value` over its `limit` (same units), clipped to [-1, 1] as `np.clip` clips it
    (NaN stays NaN): `to_env_action`'s law, which the batch's ego actuation compiles too."""
    return min(max(value / limit, -1.0), 1.0)


class HighwayAdapter:
    """Owns one highway-v0 env; `reset(seed)` and `step(actuation)` return `WorldState` snapshots."""

    def __init__(
        self,
        highway: HighwayConfig,
        backend: Backend = "vector",
        render: bool = False,
        plant: PlantName = "kinematic",
    ) -> None:
        if backend not in BACKENDS:
            raise ValueError(unknown_name("simulation backend", backend, BACKENDS))
        self.config = highway
        self.dt = 1.0 / highway.simulation_frequency
        self.env = gym.make(
            ENV_IDS[highway.road][backend],
            config=env_config(highway, plant),
            render_mode="rgb_array" if render else None,
            disable_env_checker=True,
        )
        self.road_env: AbstractEnv = self.env.unwrapped
        self.renders = render
        self.terminated = False
        self.truncated = False

    def reset(self, seed: int) -> WorldState:
        self.env.reset(seed=seed)
        env: AbstractEnv = self.env.unwrapped
        stabilised(env.vehicle)
        self.terminated = self.truncated = False
        return self.snapshot()

    def step(self, actuation: Actuation) -> WorldState:
        """Apply one actuation for one physics frame.

        Unless it renders, the env steps without the work whose result the stack discards: its
        `step` is `time`, `_simulate`, observation, reward, the end flags and the info dict (which
        computes the rewards again); only `time`, `_simulate` and the end flags change or read the
        world, so the road evolves exactly as through `env.step`."""
        action = to_env_action(actuation)
        env = self.road_env
        if self.renders:
            _, _, self.terminated, self.truncated, _ = self.env.step(action)
        else:
            env.time += 1 / env.config["policy_frequency"]
            env._simulate(action)
            self.terminated, self.truncated = env._is_terminated(), env._is_truncated()
        take_moved = getattr(env.road, "take_moved", None)
        return self.snapshot(take_moved() if take_moved is not None else None)

    def show_intent(self, lane: int) -> None:
        """Show the traffic the lane the ego is changing into (-1: none) for the frames that follow:
        a yielding driver in it eases off (`stack.sim.vector.habits`); other roads ignore it."""
        self.road_env.road.ego_intent_lane = lane

    @property
    def done(self) -> bool:
        return self.terminated or self.truncated

    def render(self) -> np.ndarray:
        """The current frame as an RGB array (the env must be created with `render=True`)."""
        # gymnasium types render() for every render mode; with rgb_array it is one RGB array
        return cast(np.ndarray, self.env.render())

    def render_scale(self) -> tuple[float, float]:
        """How `render` maps the road: pixels per metre, and the ego's x in the frame [px]
        (highway-env centres its view on the ego at `centering_position`)."""
        env: AbstractEnv = self.env.unwrapped
        config = env.config
        return float(config["scaling"]), float(config["centering_position"][0]) * config["screen_width"]

    @property
    def rendering(self) -> bool:
        return self.env.unwrapped.render_mode == "rgb_array"

    def close(self) -> None:
        self.env.close()

    def __enter__(self) -> HighwayAdapter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def snapshot(self, moved: Moved | None = None) -> WorldState:
        """Copy the road into a `WorldState` (row 0 = ego, others in road order); `moved`: where the
        step just taken left the vehicles, if the road says."""
        env: AbstractEnv = self.env.unwrapped
        return snapshot(env.road, env.vehicle, float(env.time), int(env.config["lanes_count"]), moved)


def world_state(env: gym.Env) -> WorldState:
    """The `WorldState` of any highway-env env (yours, made with `gym.make`): its controlled vehicle
    as the ego, every other vehicle of its road."""
    road_env: AbstractEnv = env.unwrapped
    return snapshot(road_env.road, road_env.vehicle, float(road_env.time))


def snapshot(
    road: Road, ego: Vehicle, time: float, lanes_count: int | None = None, moved: Moved | None = None
) -> WorldState:
    """The road at `time` [s] as a `WorldState`: row 0 = `ego`, the others in road order, in the
    frame of lane 0 of the ego's road segment, which continues across straight segments, so the
    vehicles of the segments ahead and behind are seen too. Only the segment's first `lanes_count`
    lanes are driven (an exit lane that opens for a while is not). `moved`: the road's vehicles
    where the frame just stepped left them (their state as arrays already, read instead of the
    vehicles when they are still the road's)."""
    road_vehicles = road.vehicles
    ego_index = road_vehicles.index(ego)
    order = [ego_index, *range(ego_index), *range(ego_index + 1, len(road_vehicles))]
    vehicles = [ego, *road_vehicles[:ego_index], *road_vehicles[ego_index + 1 :]]
    start, end, _ = ego.lane_index
    lanes = tuple(road.network.graph[start][end])[:lanes_count]
    reference = lanes[0]
    ids = np.array(order)
    if moved is not None and moved.vehicles == road_vehicles:
        footprints = moved.footprints
        position = np.stack([footprints.x[ids], footprints.y[ids]], axis=1)
        heading, speed = footprints.heading[ids], footprints.speed[ids]
        length, width, lane = footprints.length[ids], footprints.width[ids], moved.lane_id[ids]
        crashed = np.array([v.crashed for v in vehicles], dtype=float)
    else:
        position = np.array([v.position for v in vehicles], dtype=float)
        heading, speed, length, width, crashed, lane = columns(vehicles, _vehicle_state)
    velocity = np.empty((len(vehicles), 2))
    velocity[:, 0], velocity[:, 1] = speed * np.cos(heading), speed * np.sin(heading)
    s, d = _lane_frame(reference, position)
    lateral_speed, yaw_rate = _body_rates(ego)
    return WorldState(
        time=time,
        ids=ids,
        position=position,
        heading=heading,
        speed=speed,
        velocity=velocity,
        lane=lane.astype(int),
        length=length,
        width=width,
        s=s,
        d=d,
        crashed=crashed.astype(bool),
        lanes=lanes,
        lane_offsets=_lane_offsets(lanes, float(s[0])),
        ego_lateral_speed=lateral_speed,
        ego_yaw_rate=yaw_rate,
    )


def _vehicle_state(vehicle: Vehicle) -> tuple[float, float, float, float, bool, int]:
    """What a snapshot keeps of a vehicle besides its position: heading [rad], speed [m/s], length
    and width [m], whether it crashed, its lane id (-1 off the road)."""
    lane_index = vehicle.lane_index
    return (
        vehicle.heading,
        vehicle.speed,
        vehicle.LENGTH,
        vehicle.WIDTH,
        vehicle.crashed,
        lane_index[2] if lane_index else -1,
    )


_STEADY_OFFSETS: weakref.WeakKeyDictionary[AbstractLane, tuple[tuple[weakref.ref, ...], np.ndarray]] = (
    weakref.WeakKeyDictionary()
)
"""Lane offsets that do not depend on s, by reference lane: (the lanes, the offsets)."""


def _lane_offsets(lanes: tuple[AbstractLane, ...], s: float) -> np.ndarray:
    """Lateral offset [m] of each lane's centre at `s` in the frame of `lanes[0]`. On straight lanes
    whose axes are the coordinate axes every product is by 0 or +-1, so the offset is the same bits
    at any finite s, and is computed once per set of lanes."""
    reference = lanes[0]
    steady = _STEADY_OFFSETS.get(reference)
    if (
        steady is not None
        and math.isfinite(s)
        and len(steady[0]) == len(lanes)
        and all(ref() is lane for ref, lane in zip(steady[0], lanes, strict=True))
    ):
        return steady[1].copy()
    offsets = np.array([reference.local_coordinates(lane.position(s, 0.0))[1] for lane in lanes])
    if math.isfinite(s) and all(type(lane) is StraightLane and _on_axes(lane) for lane in lanes):
        _STEADY_OFFSETS[reference] = (tuple(weakref.ref(lane) for lane in lanes), offsets.copy())
    return offsets


def _on_axes(lane: StraightLane) -> bool:
    """Whether the lane's direction and its normal are coordinate axes (+-1 and 0 components)."""
    return all(
        sorted(np.abs(axis).tolist()) == [0.0, 1.0] for axis in (lane.direction, lane.direction_lateral)
    )


def _body_rates(vehicle: Vehicle) -> tuple[float, float]:
    """(lateral speed [m/s], yaw rate [rad/s]) in the body frame: the dynamic bicycle's states, or
    the kinematic bicycle's (`kinematic_body_rates`) for its last steering."""
    if isinstance(vehicle, BicycleVehicle):
        return float(vehicle.lateral_speed), float(vehicle.yaw_rate)
    return kinematic_body_rates(vehicle.speed, float(vehicle.action.get("steering", 0.0)), vehicle.LENGTH)


def kinematic_body_rates(speed: float, steering: float, length: float) -> tuple[float, float]:
    """The kinematic bicycle's (lateral speed [m/s], yaw rate [rad/s]) in the body frame at `speed`
    [m/s] and `steering` [rad], `length` [m] long: v sin(beta) and v sin(beta) / (L/2), beta the
    slip angle arctan(tan(steering) / 2)."""
    beta = np.arctan(0.5 * np.tan(steering))
    lateral = float(speed * np.sin(beta))
    return lateral, lateral / (length / 2)


def _lane_frame(lane: AbstractLane, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s, d) of each position in `lane`'s frame; one matrix product on straight lanes."""
    if isinstance(lane, StraightLane):
        delta = position - lane.start
        return delta @ lane.direction, delta @ lane.direction_lateral
    coordinates = np.array([lane.local_coordinates(p) for p in position], dtype=float)
    return coordinates[:, 0], coordinates[:, 1]
