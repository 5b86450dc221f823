"""The decision layer: agents behind one protocol (`predict` on an encoding of the grid), built by
name (`make_agent`) or loaded from a safe model file (`load_agent`), and `decide` -> a `Command`."""

import common.numba_cache  # noqa: F401  numba's cache folder is set before anything here compiles
from planner.agents import Agent, decide
from planner.factory import make_agent
from records import Command

__all__ = ["Agent", "Command", "decide", "load_agent", "make_agent"]


def load_agent(path: str, expected_algorithms: tuple[str, ...] | None = None) -> Agent:
    """A learned agent from a model file (data only, never unpickled; torch is imported then);
    see `planner.learned`."""
    from planner.learned import load_agent as load

    return load(path, expected_algorithms)
