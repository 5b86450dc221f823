"""Heterogeneous traffic for highway-v0: vehicle classes with their own desired speeds and lengths,
and the ego spawned inside the traffic rather than behind it.

highway-env spawns the ego first and every other vehicle ahead of the furthest one, so the ego starts
behind all of them and meets a platoon that has settled at the speed of its slowest members: lane
choice is then worth little. `ScenarioTraffic._create_vehicles` keeps highway-env's own vehicles,
behaviours (IDM + MOBIL) and placement rule, and only (1) spawns `ego_position` of the traffic before
the ego, so that part is behind it, and (2) gives each vehicle a class drawn by share, with its
desired (IDM target) speed and length drawn from the class's ranges, a lane from the class's lanes,
MOBIL lane changes on or off and an IDM jam distance that grows with its length, and (3) keeps every
start drivable: a vehicle placed closer ahead of the last one in its lane (the ego or traffic) than
both half-lengths, UN R157's minimum following distance at the follower's speed and room to slow to
its own (`make_room`, `common.r157.start_gap`) is moved forward, so no episode opens with a brake.
Every draw comes
from the env's seeded generator, so the same seed gives the same traffic. Without `traffic` in the
config, highway-env's own placement runs, with the same draws; its starts are made feasible too only
where `feasible_spawns` asks (the stack's roads: `stack.sim.highway.env_config`), so the gym ids
`drivestack/Highway-v0`, `FastHighway-v0` and `VectorHighway-v0` made with highway-v0's config give
highway-v0's traffic, vehicle for vehicle.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from highway_env import utils
from highway_env.envs.exit_env import ExitEnv
from highway_env.envs.highway_env import HighwayEnv
from highway_env.road.lane import StraightLane
from highway_env.road.road import Road
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle

from common.r157 import start_room
from stack.settings.world import EGO_LENGTH_M, EGO_SPAWN_SPEED_MPS
from stack.sim.drivers import assign_drivers
from stack.sim.spawns import lane_coordinates, make_room

IDM_JAM_CLEARANCE = 5.0
"""highway-env's IDM jam distance is 5 m + the vehicle's length (centre to centre); scaled with each
vehicle's own length, a truck stopped behind a truck keeps its 5 m instead of overlapping it [m]."""


class TrafficVehicle(IDMVehicle):
    """highway-env's IDM + MOBIL vehicle that stops where stock's drives backwards. Closer to its
    leader than its jam distance, the IDM keeps braking at a standstill, and stock's vehicle then
    reverses (down to `MIN_SPEED`, -40 m/s): in a queue it backs into the car behind, and one that
    was changing lane swings its nose further into the next lane as it goes. Here a frame's braking
    ends at speed 0 [m/s] (to float rounding, ~1e-16 m/s); everything else is stock."""

    def stop_at_standstill(self, dt: float) -> None:
        """Limit this frame's braking so that `dt` [s] of it ends at speed 0 at the lowest."""
        if not self.crashed:
            self.action["acceleration"] = max(float(self.action["acceleration"]), -self.speed / dt)

    def step(self, dt: float) -> None:
        self.stop_at_standstill(dt)
        super().step(dt)

    @classmethod
    def create_random(
        cls,
        road: Road,
        speed: float | None = None,
        lane_from: str | None = None,
        lane_to: str | None = None,
        lane_id: int | None = None,
        spacing: float = 1,
    ) -> TrafficVehicle:
        """highway-env's `Vehicle.create_random`: the same draws in the same order and the same
        vehicle, with the start behind the last vehicle read from every position at once
        (`lane_coordinates`) instead of one `local_coordinates` call per vehicle (a road of n vehicles
        spawns in n^2 of them)."""
        rng = road.np_random
        _from = lane_from or uniform_choice(rng, list(road.network.graph.keys()))
        _to = lane_to or uniform_choice(rng, list(road.network.graph[_from].keys()))
        _id = lane_id if lane_id is not None else int(rng.integers(len(road.network.graph[_from][_to])))
        lane = road.network.get_lane((_from, _to, _id))
        if speed is None:
            if lane.speed_limit is not None:
                speed = rng.uniform(0.7 * lane.speed_limit, 0.8 * lane.speed_limit)
            else:
                speed = rng.uniform(Vehicle.DEFAULT_INITIAL_SPEEDS[0], Vehicle.DEFAULT_INITIAL_SPEEDS[1])
        default_spacing = 12 + 1.0 * speed
        offset = spacing * default_spacing * np.exp(-5 / 40 * len(road.network.graph[_from][_to]))
        positions = [v.position for v in road.vehicles]
        x0 = np.max(lane_coordinates(lane, positions)[0]) if len(road.vehicles) else 3 * offset
        x0 += offset * rng.uniform(0.9, 1.1)
        return cls(road, lane.position(x0, 0), lane.heading_at(x0), speed)


TRAFFIC_VEHICLE = f"{TrafficVehicle.__module__}.{TrafficVehicle.__qualname__}"
"""The `other_vehicles_type` the stack's roads are filled with."""
IDM_DRIVERS = (IDMVehicle, TrafficVehicle)
"""Vehicle classes driven by highway-env's IDM + MOBIL `act`, unchanged."""


@cache
def vehicle_class(path: str) -> type[Vehicle]:
    """highway-env's `utils.class_from_path(path)`, imported once per path rather than per vehicle."""
    return utils.class_from_path(path)


def uniform_choice(rng: np.random.Generator, items: list[Any]) -> Any:
    """`rng.choice(items)`: the same draw (`integers(0, len(items))`) without the list's copy to
    an array, and the item itself."""
    return items[int(rng.integers(len(items)))]


def cumulative_class_odds(classes: list[dict[str, Any]]) -> np.ndarray:
    """Each vehicle class's cumulative probability (its share over their sum), as
    `Generator.choice(p=...)` makes it of the probabilities: the classes' cumulative sum over its
    last value."""
    shares = np.array([c["share"] for c in classes])
    odds: np.ndarray = (shares / shares.sum()).cumsum()
    odds /= odds[-1]
    return odds


def _spawn_other(
    env: HighwayEnv, classes: list[dict[str, Any]], odds: np.ndarray, spawn_speed: float | None
) -> None:
    """One traffic vehicle of a class drawn by its cumulative odds (`cumulative_class_odds`: the draw of
    `rng.choice(len(classes), p=...)`), behind-the-last rule of highway-env."""
    rng = env.np_random
    kind = classes[int(np.searchsorted(odds, rng.random(), side="right"))]
    desired = float(rng.uniform(*kind["speed_mps"]))
    length = float(rng.uniform(*kind["length_m"]))
    vehicle_type = vehicle_class(env.config["other_vehicles_type"])
    lane = int(uniform_choice(rng, kind["lanes"])) if kind.get("lanes") else None
    vehicle = vehicle_type.create_random(
        env.road, speed=spawn_speed or desired, lane_id=lane, spacing=1 / env.config["vehicles_density"]
    )
    vehicle.randomize_behavior()
    vehicle.enable_lane_change = kind.get("changes_lane", True)
    vehicle.target_speed = desired
    vehicle.LENGTH = length
    vehicle.DISTANCE_WANTED = IDM_JAM_CLEARANCE + length
    vehicle.diagonal = float(np.sqrt(length**2 + vehicle.WIDTH**2))
    make_room(env, vehicle)
    env.road.vehicles.append(vehicle)


def _place_incident(env: HighwayEnv, incident: dict[str, Any]) -> None:
    """A stopped vehicle `incident["ahead_m"]` ahead of the ego in `incident["lane"]`; the traffic
    vehicles it would overlap, or that could not stop behind it, leave the road. A plain kinematic
    `Vehicle` with no action: it stays where it is (an IDM vehicle with target speed 0 would not:
    highway-env's IDM treats 0 as 0.01 m/s and pulls away from standstill at 3 m/s^2)."""
    ego = env.vehicle
    lane_index = (*ego.lane_index[:2], int(incident["lane"]))
    lane = env.road.network.get_lane(lane_index)
    s_stop = lane.local_coordinates(ego.position)[0] + float(incident["ahead_m"])
    stopped = Vehicle(env.road, lane.position(s_stop, 0.0), lane.heading_at(s_stop), 0.0)
    stopped.LENGTH = float(incident["length_m"])
    stopped.diagonal = float(np.sqrt(stopped.LENGTH**2 + stopped.WIDTH**2))

    def blocked(other: Vehicle) -> bool:
        if other is ego or other.lane_index != lane_index:
            return False
        ahead = s_stop - lane.local_coordinates(other.position)[0]
        room = start_room(other.speed, 0.0, other.LENGTH, stopped.LENGTH)
        return -(other.LENGTH + stopped.LENGTH) / 2 < ahead < room

    env.road.vehicles = [other for other in env.road.vehicles if not blocked(other)]
    env.road.vehicles.append(stopped)


INCIDENT_AHEAD_M = (150.0, 350.0)
"""Where a random world's stopped car stands ahead of the ego at spawn [m], and at least the ego's
start room (`common.r157.start_room`) at its spawn speed."""
INCIDENT_LENGTH_M = 5.0
"""A random world's stopped car's length [m]."""
SLOWEST_TRUCK_MPS = 2.0
"""The lowest desired speed a random world's trucks are given [m/s]."""


def random_traffic(rng: np.random.Generator, ranges: dict[str, Any]) -> dict[str, Any]:
    """highway-env config keys (`lanes_count`, `vehicles_count`, `vehicles_density`, `traffic`) of
    one world drawn from `ranges` (a `RandomTrafficConfig` as data)."""

    def draw(key: str) -> float:
        return float(rng.uniform(*ranges[key]))

    lanes = int(rng.integers(ranges["lanes_count"][0], ranges["lanes_count"][1] + 1))
    car_low = draw("car_speed_mps")
    car_speeds = [car_low, car_low + draw("car_spread_mps")]
    slower = draw("truck_slower_mps")
    truck_speeds = [max(speed - slower, SLOWEST_TRUCK_MPS) for speed in car_speeds]
    trucks_change_lane = bool(rng.random() < ranges["trucks_change_lane"])
    truck_lanes = [0, 1] if rng.random() < ranges["trucks_keep_left"] else [lanes - 2, lanes - 1]
    truck_share = draw("truck_share")
    car: dict[str, Any] = {
        "name": "car",
        "share": 1.0 - truck_share,
        "speed_mps": car_speeds,
        "length_m": [4.5, 5.0],
    }
    truck: dict[str, Any] = {
        "name": "truck",
        "share": truck_share,
        "speed_mps": truck_speeds,
        "length_m": [10.0, 12.0],
        "lanes": None if trucks_change_lane else truck_lanes,
        "changes_lane": trucks_change_lane,
    }
    traffic: dict[str, Any] = {
        "classes": [kind for kind in (car, truck) if kind["share"] > 0],
        "ego_position": draw("ego_position"),
        "spawn_speed_mps": sum(truck_speeds) / 2,
    }
    if rng.random() < ranges["incident_probability"]:
        ego_room = start_room(traffic["spawn_speed_mps"], 0.0, EGO_LENGTH_M, INCIDENT_LENGTH_M)
        traffic["incident"] = {
            "lane": int(rng.integers(lanes)),
            "ahead_m": max(float(rng.uniform(*INCIDENT_AHEAD_M)), ego_room),
            "length_m": INCIDENT_LENGTH_M,
        }
    return {
        "lanes_count": lanes,
        "vehicles_count": round(lanes * draw("vehicles_per_lane")),
        "vehicles_density": draw("vehicles_density"),
        "traffic": traffic,
    }


ROAD_MARGIN_M = 1000.0
"""How far past where the fastest vehicle can be at the episode's end the road still goes [m]."""


def lengthen_for_episode(road: Road, duration: float) -> None:
    """Stretch the road's straight lanes, in place, so that no vehicle reaches a lane's end within
    `duration` [s] even at highway-env's top speed (`Vehicle.MAX_SPEED`, 40 m/s). highway-env's
    lanes end 10 km on; past the end a vehicle no longer sees its leader (`is_reachable_from` stops
    there), so long episodes ended in collisions. A road already long enough is left as it is."""
    if not road.vehicles:
        return
    positions = [vehicle.position for vehicle in road.vehicles]
    for lanes in (lanes for ends in road.network.graph.values() for lanes in ends.values()):
        for lane in lanes:
            if type(lane) is not StraightLane:
                continue
            front = float(np.max(lane_coordinates(lane, positions)[0]))
            needed = front + Vehicle.MAX_SPEED * duration + ROAD_MARGIN_M
            if needed > lane.length:
                lane.end = lane.start + lane.direction * needed
                lane.length = needed


def configured_drivers(config: dict[str, Any]) -> Any:
    """The driver population (`stack.sim.drivers`) an env config asks for: `traffic.drivers`, or
    `random_traffic.drivers` (a random world's `traffic` is drawn without it); None: highway-env's."""
    for key in ("random_traffic", "traffic"):
        section = config.get(key)
        if isinstance(section, dict) and section.get("drivers") is not None:
            return section["drivers"]
    return None


class ScenarioTraffic(HighwayEnv):
    """highway-v0 whose `_create_vehicles` reads `config["traffic"]` (see the module docstring), and
    whose `_reset` draws the road's traffic first when `config["random_traffic"]` is set. Without
    either, and without `config["feasible_spawns"]`, it is highway-v0."""

    @classmethod
    def default_config(cls) -> dict:
        return {**super().default_config(), "feasible_spawns": False}

    def _reset(self) -> None:
        ranges = self.config.get("random_traffic")
        if ranges:
            self.config.update(random_traffic(self.np_random, ranges))
        super()._reset()
        lengthen_for_episode(self.road, float(self.config["duration"]))
        self.drivers_drawn = assign_drivers(
            self.road.vehicles,
            configured_drivers(self.config),
            self.np_random,
            IDM_DRIVERS,
            float(self.config["simulation_frequency"]),
        )
        self.road.ego = self.vehicle

    def _create_highway_env_vehicles(self) -> None:
        """highway-env's own `_create_vehicles` (the ego at 25 m/s behind all the traffic, the same
        draws in the same order), with every start made feasible by `make_room` when
        `feasible_spawns` is set."""
        other_type = vehicle_class(self.config["other_vehicles_type"])
        spawned = Vehicle.create_random(
            self.road,
            speed=EGO_SPAWN_SPEED_MPS,
            lane_id=self.config["initial_lane_id"],
            spacing=self.config["ego_spacing"],
        )
        ego = self.action_type.vehicle_class(self.road, spawned.position, spawned.heading, spawned.speed)
        self.controlled_vehicles = [ego]
        self.road.vehicles.append(ego)
        for _ in range(self.config["vehicles_count"]):
            vehicle = other_type.create_random(self.road, spacing=1 / self.config["vehicles_density"])
            vehicle.randomize_behavior()
            if self.config["feasible_spawns"]:
                make_room(self, vehicle)
            self.road.vehicles.append(vehicle)

    def _create_vehicles(self) -> None:
        traffic = self.config.get("traffic")
        if not traffic or not traffic.get("classes"):
            self._create_highway_env_vehicles()
            return
        classes = list(traffic["classes"])
        odds = cumulative_class_odds(classes)
        spawn_speed = traffic.get("spawn_speed_mps")
        count = self.config["vehicles_count"]
        behind = round(traffic["ego_position"] * count)
        for _ in range(behind):
            _spawn_other(self, classes, odds, spawn_speed)
        spawned = Vehicle.create_random(
            self.road,
            speed=spawn_speed or EGO_SPAWN_SPEED_MPS,
            lane_id=self.config["initial_lane_id"],
            spacing=self.config["ego_spacing"],
        )
        ego = self.action_type.vehicle_class(self.road, spawned.position, spawned.heading, spawned.speed)
        self.controlled_vehicles = [ego]
        make_room(self, ego)
        self.road.vehicles.append(ego)
        for _ in range(count - behind):
            _spawn_other(self, classes, odds, spawn_speed)
        if traffic.get("incident"):
            _place_incident(self, traffic["incident"])


class ExitTraffic(ExitEnv):
    """exit-v0 with every start made drivable by `make_room` when `config["feasible_spawns"]` is
    set (the stack's exit road); without it, exit-v0 vehicle for vehicle."""

    @classmethod
    def default_config(cls) -> dict:
        return {**super().default_config(), "feasible_spawns": False}

    def _create_vehicles(self) -> None:
        """exit-v0's own spawn (the ego at 25 m/s in lane 0 behind the traffic, the same draws in
        the same order), each traffic vehicle moved forward by `make_room` as it is placed."""
        if not self.config["feasible_spawns"]:
            super()._create_vehicles()
            return
        spawned = Vehicle.create_random(
            self.road,
            speed=EGO_SPAWN_SPEED_MPS,
            lane_from="0",
            lane_to="1",
            lane_id=0,
            spacing=self.config["ego_spacing"],
        )
        ego = self.action_type.vehicle_class(self.road, spawned.position, spawned.heading, spawned.speed)
        self.controlled_vehicles = [ego]
        self.road.vehicles.append(ego)
        other_type = vehicle_class(self.config["other_vehicles_type"])
        lanes = np.arange(self.config["lanes_count"])
        for _ in range(self.config["vehicles_count"]):
            lane_id = self.road.np_random.choice(lanes, size=1, p=lanes / lanes.sum()).astype(int)[0]
            lane = self.road.network.get_lane(("0", "1", lane_id))
            vehicle = other_type.create_random(
                self.road,
                lane_from="0",
                lane_to="1",
                lane_id=lane_id,
                speed=lane.speed_limit,
                spacing=1 / self.config["vehicles_density"],
            ).plan_route_to("3")
            vehicle.enable_lane_change = False
            make_room(self, vehicle)
            self.road.vehicles.append(vehicle)
