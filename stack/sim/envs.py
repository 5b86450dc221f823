"""Gymnasium registrations of the stack. `import stack` asks for them without importing gymnasium
(and numpy with it), so the CLI starts light: they are made at once when gymnasium is already
imported, else the moment it is (`register_when_imported`)."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from importlib.machinery import ModuleSpec
from types import ModuleType

HIGHWAY = "drivestack/Highway-v0"
FAST_HIGHWAY = "drivestack/FastHighway-v0"
VECTOR_HIGHWAY = "drivestack/VectorHighway-v0"
FAST_HIGHWAY_FAST = "drivestack/FastHighwayFast-v0"
EXIT = "drivestack/Exit-v0"
FAST_EXIT = "drivestack/FastExit-v0"
HIERARCHICAL_HIGHWAY = "drivestack/HierarchicalHighway-v0"
DEEPCARS = "drivestack/DeepCars-v0"


def register_envs() -> None:
    import gymnasium as gym

    if FAST_HIGHWAY in gym.registry:
        return
    gym.register(HIGHWAY, entry_point="stack.sim.traffic:ScenarioTraffic")
    gym.register(FAST_HIGHWAY, entry_point="stack.sim.fast_road:FastHighwayEnv")
    gym.register(VECTOR_HIGHWAY, entry_point="stack.sim.vector.road:VectorHighwayEnv")
    gym.register(FAST_HIGHWAY_FAST, entry_point="stack.sim.fast_road:FastHighwayEnvFast")
    gym.register(EXIT, entry_point="stack.sim.traffic:ExitTraffic")
    gym.register(FAST_EXIT, entry_point="stack.sim.fast_road:FastExitEnv")
    gym.register(
        HIERARCHICAL_HIGHWAY,
        entry_point="stack.training.decision_env:HierarchicalHighwayEnv",
        vector_entry_point="stack.training.gym_vector_env:HierarchicalHighwayVectorEnv",
    )
    gym.register(DEEPCARS, entry_point="stack.deepcars.world:DeepCarsEnv")


def register_when_imported() -> None:
    """The envs registered now if gymnasium is imported, else as soon as it is."""
    if "gymnasium" in sys.modules:
        register_envs()
    elif not any(isinstance(finder, _AfterGymnasium) for finder in sys.meta_path):
        sys.meta_path.insert(0, _AfterGymnasium())


class _AfterGymnasium:
    """A finder on `sys.meta_path` for one import: it finds gymnasium as the other finders would and
    has its loader register the envs once gymnasium's own code has run, then leaves."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        if fullname != "gymnasium":
            return None
        import importlib.util

        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        if spec is not None and spec.loader is not None:
            run = spec.loader.exec_module

            def exec_then_register(module: ModuleType) -> None:
                run(module)
                register_envs()

            setattr(spec.loader, "exec_module", exec_then_register)  # noqa: B010
        return spec
