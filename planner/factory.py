"""Agents by name."""

from __future__ import annotations

from perception.grid import GridConfig
from planner.agents import Agent, FreeGapAgent, KeepLaneAgent, RandomAgent

AGENT_NAMES = ("rule", "keep-lane", "random")


def make_agent(name: str, lanes: int, grid: GridConfig, seed: int = 0, model=None) -> Agent:
    """Build the agent `name` for a road of `lanes` lanes seen through `grid`; learned agents load
    `model` (a path)."""
    if name == "rule":
        return FreeGapAgent(lanes, grid)
    if name == "keep-lane":
        return KeepLaneAgent()
    if name == "random":
        return RandomAgent(seed)
    raise ValueError(f"unknown agent {name!r}; available: {', '.join(AGENT_NAMES)}")
