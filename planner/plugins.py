"""Agents from outside the package: a class by path or an installed entry point (`records.plugins`),
built for the run and checked against the `Agent` protocol before any episode."""

from __future__ import annotations

from pathlib import Path

from planner.agents import Agent
from records import ENCODINGS, GridConfig
from records.plugins import AGENT_GROUP, PluginError, construct, load_class

PROTOCOL = (
    "an agent: attributes encoding (one of " + ", ".join(ENCODINGS) + ") and grid_config "
    "(a GridConfig or None) and a method predict(observation, state=None, episode_start=None, "
    "deterministic=True) -> (action, state)"
)


def plugin_agent(value: str, lanes: int, grid: GridConfig, seed: int, model: Path | str | None) -> Agent:
    """The agent class `value` names, built with whichever of `lanes`, `grid`, `seed` and `model`
    (the --model path, None without) its constructor takes; PluginError (one line) when it does
    not load, build, or fit `PROTOCOL`."""
    cls = load_class(value, AGENT_GROUP)
    offered = {"lanes": lanes, "grid": grid, "seed": seed, "model": None if model is None else str(model)}
    agent = construct(cls, offered, value)
    problem = None
    if not isinstance(agent, Agent) or not callable(getattr(agent, "predict", None)):
        problem = "it lacks encoding, grid_config or predict"
    elif agent.encoding not in ENCODINGS:
        problem = f"its encoding is {agent.encoding!r}"
    elif agent.grid_config is not None and not isinstance(agent.grid_config, GridConfig):
        problem = f"its grid_config is a {type(agent.grid_config).__name__}"
    if problem:
        raise PluginError(f"{value}: not {PROTOCOL}; {problem}")
    return agent
