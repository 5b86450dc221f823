"""Agents from outside the package: a class by path or an installed entry point (`common.plugins`),
built for the run and checked against the `Agent` protocol before any episode."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from common.plugins import AGENT_GROUP, PluginError, bad_return, construct, failed_call, load_class
from planner.agents import Agent, Prediction
from records import ENCODINGS, N_ACTIONS, Command, Encoding, GridConfig

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
    return GuardedAgent(agent, value)


ACTION = f"one action index, an integer 0-{N_ACTIONS - 1} ({', '.join(c.name for c in Command)})"


class GuardedAgent:
    """A plug-in agent whose `predict` is checked at every call: an exception it raises, or an
    action that is not one integer index of `Command` (a float, a bool, several values), is
    `PluginFailed` naming the plug-in, never coerced into a command. Every other attribute is the
    plug-in's own."""

    def __init__(self, agent: Agent, name: str) -> None:
        self.agent, self.name = agent, name

    @property
    def encoding(self) -> Encoding:
        return self.agent.encoding

    @property
    def grid_config(self) -> GridConfig | None:
        return self.agent.grid_config

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> Prediction:
        try:
            prediction = self.agent.predict(observation, state, episode_start, deterministic)
            action, state = prediction
        except (Exception, SystemExit) as error:  # noqa: BLE001 - user code may raise or exit
            raise failed_call(self.name, "predict", error) from None
        values = np.asarray(action) if isinstance(action, np.ndarray | np.integer | int) else None
        if (
            values is None
            or isinstance(action, bool)
            or values.size != 1
            or values.dtype.kind not in "iu"
            or not 0 <= int(values.reshape(-1)[0]) < N_ACTIONS
        ):
            raise bad_return(self.name, "predict", action, ACTION)
        return action, state

    def __getattr__(self, name: str) -> Any:
        return getattr(self.agent, name)
