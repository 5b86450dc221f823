"""Gymnasium registrations of the stack (run on `import stack`)."""

from __future__ import annotations

import gymnasium as gym

HIGHWAY = "drivestack/Highway-v0"
FAST_HIGHWAY = "drivestack/FastHighway-v0"
VECTOR_HIGHWAY = "drivestack/VectorHighway-v0"
FAST_HIGHWAY_FAST = "drivestack/FastHighwayFast-v0"
FAST_EXIT = "drivestack/FastExit-v0"
HIERARCHICAL_HIGHWAY = "drivestack/HierarchicalHighway-v0"
DEEPCARS = "drivestack/DeepCars-v0"


def register_envs() -> None:
    if FAST_HIGHWAY in gym.registry:
        return
    gym.register(HIGHWAY, entry_point="stack.sim.traffic:ScenarioTraffic")
    gym.register(FAST_HIGHWAY, entry_point="stack.sim.fast_road:FastHighwayEnv")
    gym.register(VECTOR_HIGHWAY, entry_point="stack.sim.vector.road:VectorHighwayEnv")
    gym.register(FAST_HIGHWAY_FAST, entry_point="stack.sim.fast_road:FastHighwayEnvFast")
    gym.register(FAST_EXIT, entry_point="stack.sim.fast_road:FastExitEnv")
    gym.register(HIERARCHICAL_HIGHWAY, entry_point="stack.core.decision_env:HierarchicalHighwayEnv")
    gym.register(DEEPCARS, entry_point="stack.deepcars.world:DeepCarsEnv")
