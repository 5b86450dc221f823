"""One vehicle on an empty three-lane highway-env road, straight or a bend: the plant of
`drivestack track`, stepped like the highway adapter so the closed loop drives it unchanged.

The vehicle is highway-env's kinematic bicycle (`Vehicle`), its dynamic bicycle with tyre slip
(`BicycleVehicle`), or, for the `builtin` baseline, its own `ControlledVehicle`, whose steering and
speed laws `BuiltinDriver` hands the loop as a controller.
"""

from __future__ import annotations

import math
import time
from typing import Literal

import numpy as np
from highway_env.road.lane import AbstractLane, CircularLane, LineType
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.dynamics import BicycleVehicle
from highway_env.vehicle.kinematics import Vehicle

from records import Actuation, EgoState, Reference, WorldState
from stack.sim.highway import snapshot
from stack.sim.plant import StableBicycleVehicle

RoadKind = Literal["straight", "bend-1000", "bend-500"]
PlantKind = Literal["kinematic", "dynamic", "builtin"]
LANE_WIDTH = 4.0
"""[m]"""
BEND_RADIUS: dict[RoadKind, float] = {"bend-1000": 1000.0, "bend-500": 500.0}
"""Radius of lane 0 of each left-hand bend [m]."""
START_S = 100.0
"""Where the vehicle starts along its lane [m]."""
START_LANE = 1
"""The middle lane."""


def road_network(kind: RoadKind) -> RoadNetwork:
    """Three lanes, straight (10 km) or a left-hand bend of `BEND_RADIUS[kind]`."""
    if kind == "straight":
        return RoadNetwork.straight_road_network(3, length=10000)
    network = RoadNetwork()
    for k in range(3):
        network.add_lane(
            "a",
            "b",
            CircularLane(
                [0.0, 0.0],
                BEND_RADIUS[kind] + LANE_WIDTH * k,
                -np.pi / 2,
                np.pi / 2,
                clockwise=True,
                width=LANE_WIDTH,
                line_types=(LineType.NONE, LineType.NONE),
            ),
        )
    return network


def steady_cornering(road: Road, lane: AbstractLane, speed: float, dynamic: bool) -> Vehicle:
    """A bicycle at START_S on `lane`'s centre in the steady state of following it, as a car
    already driving the bend would be: yaw rate r = v kappa [rad/s] and the sideslip beta that
    puts its course along the lane (heading = lane heading - beta). Kinematic bicycle: beta =
    asin(r L / 2v) = asin(kappa L / 2). Dynamic bicycle (Rajamani's 2.21-2.22 in steady state):
    beta = r (b / v - m a v / (C_r L)) = kappa (b - m a v^2 / (C_r L)), C_r the rear axle's
    cornering stiffness; without that start it would first have to settle into the turn. Both are
    written without dividing by v, so a car can start at standstill."""
    curvature = lane.heading_at(START_S + 0.5) - lane.heading_at(START_S - 0.5)
    yaw_rate = speed * curvature
    position, lane_heading = lane.position(START_S, 0.0), lane.heading_at(START_S)
    if not dynamic:
        slip = math.asin(Vehicle.LENGTH / 2 * curvature)
        vehicle = Vehicle(road, position, lane_heading - slip, speed)
        vehicle.action = {"steering": math.atan(2 * math.tan(slip)), "acceleration": 0.0}
        return vehicle
    b, m, a = BicycleVehicle.LENGTH_B, BicycleVehicle.MASS, BicycleVehicle.LENGTH_A
    stiffness_rear = 2 * BicycleVehicle.FRICTION_REAR
    slip = curvature * (b - m * a * speed**2 / (stiffness_rear * BicycleVehicle.LENGTH))
    car = StableBicycleVehicle(road, position, lane_heading - slip, speed)
    car.yaw_rate, car.lateral_speed = yaw_rate, speed * math.tan(slip)
    return car


class EmptyRoad:
    """The plant: `reset` puts the vehicle on the middle lane's centre at `speed` [m/s], `step`
    applies one actuation for `dt` seconds. Time is ticks x dt, so it is exact at every tick."""

    terminated = False
    done = False
    rendering = False

    def __init__(self, road: RoadKind, plant: PlantKind, speed: float, dt: float) -> None:
        self.road_kind, self.plant_kind, self.speed, self.dt = road, plant, speed, dt

    def reset(self, seed: int = 0) -> WorldState:
        network = road_network(self.road_kind)
        self.road = Road(network=network)
        start = next(iter(network.graph))
        end = next(iter(network.graph[start]))
        lane = network.graph[start][end][START_LANE]
        position, heading = lane.position(START_S, 0.0), lane.heading_at(START_S)
        if self.plant_kind == "builtin":
            self.vehicle: Vehicle = ControlledVehicle(
                self.road,
                position,
                heading,
                self.speed,
                target_lane_index=(start, end, START_LANE),
                target_speed=self.speed,
            )
        else:
            self.vehicle = steady_cornering(self.road, lane, self.speed, self.plant_kind == "dynamic")
        self.road.vehicles.append(self.vehicle)
        self.ticks = 0
        return self.snapshot()

    def step(self, actuation: Actuation) -> WorldState:
        Vehicle.act(self.vehicle, {"acceleration": actuation.acceleration, "steering": actuation.steering})
        self.vehicle.step(self.dt)
        self.ticks += 1
        return self.snapshot()

    def snapshot(self) -> WorldState:
        return snapshot(self.road, self.vehicle, self.ticks * self.dt)

    def render(self) -> np.ndarray:
        raise NotImplementedError("the empty road is not rendered")

    def render_scale(self) -> tuple[float, float]:
        raise NotImplementedError("the empty road is not rendered")

    def show_intent(self, lane: int) -> None:
        """The empty road has no traffic to read the ego's intent."""


class BuiltinDriver:
    """highway-env's own lane change as a controller: `ControlledVehicle`'s steering and speed
    laws, heading for the reference's target lane at once (no smooth reference)."""

    fallbacks = 0

    def __init__(self, plant: EmptyRoad) -> None:
        self.plant = plant
        self.solve_times: list[float] = []

    def reset(self) -> None:
        """Stateless: the vehicle holds its target lane and speed."""

    def step(self, state: EgoState, reference: Reference) -> Actuation:
        start_time = time.perf_counter()
        vehicle = self.plant.vehicle
        assert isinstance(vehicle, ControlledVehicle), "the builtin driver needs plant='builtin'"
        vehicle.follow_road()
        start, end, lane = vehicle.target_lane_index
        if lane != reference.target_lane:
            vehicle.target_lane_index = (start, end, reference.target_lane)
        steering = vehicle.steering_control(vehicle.target_lane_index)
        steering = float(np.clip(steering, -vehicle.MAX_STEERING_ANGLE, vehicle.MAX_STEERING_ANGLE))
        acceleration = vehicle.speed_control(vehicle.target_speed)
        self.solve_times.append(time.perf_counter() - start_time)
        return Actuation(acceleration=acceleration, steering=steering)
