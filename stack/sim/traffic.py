"""Heterogeneous traffic for highway-v0: vehicle classes with their own desired speeds and lengths,
and the ego spawned inside the traffic rather than behind it.

highway-env spawns the ego first and every other vehicle ahead of the furthest one, so the ego starts
behind all of them and meets a platoon that has settled at the speed of its slowest members: lane
choice is then worth little. `ScenarioTraffic._create_vehicles` keeps highway-env's own vehicles,
behaviours (IDM + MOBIL) and placement rule, and only (1) spawns `ego_position` of the traffic before
the ego, so that part is behind it, and (2) gives each vehicle a class drawn by share, with its
desired (IDM target) speed and length drawn from the class's ranges, a lane from the class's lanes,
MOBIL lane changes on or off and an IDM jam distance that grows with its length. Every draw comes
from the env's seeded generator, so the same seed gives the same traffic. Without `traffic` in the
config, highway-env's own `_create_vehicles` runs unchanged.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from highway_env import utils
from highway_env.envs.highway_env import HighwayEnv
from highway_env.vehicle.kinematics import Vehicle

EGO_SPAWN_SPEED = 25.0
"""highway-env's ego speed at spawn [m/s]."""

IDM_JAM_CLEARANCE = 5.0
"""highway-env's IDM jam distance is 5 m + the vehicle's length (centre to centre); scaled with each
vehicle's own length, a truck stopped behind a truck keeps its 5 m instead of overlapping it [m]."""


def _spawn_other(env: HighwayEnv, classes: list[dict[str, Any]], spawn_speed: float | None) -> None:
    """One traffic vehicle of a class drawn by share, behind-the-last rule of highway-env."""
    rng = env.np_random
    shares = np.array([c["share"] for c in classes])
    kind = classes[int(rng.choice(len(classes), p=shares / shares.sum()))]
    desired = float(rng.uniform(*kind["speed_mps"]))
    length = float(rng.uniform(*kind["length_m"]))
    vehicle_type = utils.class_from_path(env.config["other_vehicles_type"])
    lane = int(rng.choice(kind["lanes"])) if kind.get("lanes") else None
    vehicle = vehicle_type.create_random(
        env.road, speed=spawn_speed or desired, lane_id=lane, spacing=1 / env.config["vehicles_density"]
    )
    vehicle.randomize_behavior()
    vehicle.enable_lane_change = kind.get("changes_lane", True)
    vehicle.target_speed = desired
    vehicle.LENGTH = length
    vehicle.DISTANCE_WANTED = IDM_JAM_CLEARANCE + length
    vehicle.diagonal = float(np.sqrt(length**2 + vehicle.WIDTH**2))
    env.road.vehicles.append(vehicle)


class ScenarioTraffic(HighwayEnv):
    """highway-v0 whose `_create_vehicles` reads `config["traffic"]` (see the module docstring)."""

    def _create_vehicles(self) -> None:
        traffic = self.config.get("traffic")
        if not traffic:
            super()._create_vehicles()
            return
        classes = list(traffic["classes"])
        spawn_speed = traffic.get("spawn_speed_mps")
        count = self.config["vehicles_count"]
        behind = round(traffic["ego_position"] * count)
        for _ in range(behind):
            _spawn_other(self, classes, spawn_speed)
        spawned = Vehicle.create_random(
            self.road,
            speed=spawn_speed or EGO_SPAWN_SPEED,
            lane_id=self.config["initial_lane_id"],
            spacing=self.config["ego_spacing"],
        )
        ego = self.action_type.vehicle_class(self.road, spawned.position, spawned.heading, spawned.speed)
        self.controlled_vehicles = [ego]
        self.road.vehicles.append(ego)
        for _ in range(count - behind):
            _spawn_other(self, classes, spawn_speed)
