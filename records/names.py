"""The names of every swappable part (config keys and CLI options accept exactly these), the
one-line message for an unknown one, and the seeding convention."""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np
from pydantic import BeforeValidator

PolicyName = Literal["ddqn", "dqn", "tabular", "rule", "mobil", "lookahead", "keep-lane", "random"]
"""Agents that decide on an observation (`planner.factory.make_agent`)."""
AgentName = Literal[PolicyName, "oracle"]
"""Every agent a run can use: the policies and the perfect-information oracle (`stack.agents.oracle`)."""
LearnedAgentName = Literal["ddqn", "dqn", "tabular"]
Encoding = Literal["observation", "paper", "tabular"]
ControllerName = Literal["pid", "mpc", "pure-pursuit", "stanley", "lqr"]
"""The built-in trackers; a run also takes plug-ins (`common.plugins`)."""
Backend = Literal["vector", "fast", "stock"]
PlantName = Literal["kinematic", "dynamic"]
"""The ego's vehicle model: highway-env's kinematic bicycle, or its dynamic bicycle with tyre slip."""
RoadName = Literal["highway", "exit"]
"""highway-env roads the loop drives: highway-v0's straight highway, exit-v0's highway with an exit."""
POLICY_NAMES: tuple[PolicyName, ...] = get_args(PolicyName)
AGENT_NAMES: tuple[AgentName, ...] = get_args(AgentName)
LEARNED_AGENTS: tuple[LearnedAgentName, ...] = get_args(LearnedAgentName)
ENCODINGS: tuple[Encoding, ...] = get_args(Encoding)
CONTROLLER_NAMES: tuple[ControllerName, ...] = get_args(ControllerName)
BACKENDS: tuple[Backend, ...] = get_args(Backend)
PLANTS: tuple[PlantName, ...] = get_args(PlantName)
ROADS: tuple[RoadName, ...] = get_args(RoadName)


def unknown_name(kind: str, value: object, options: tuple[str, ...]) -> str:
    """The one-line message for a name that is not among `options`."""
    return f"unknown {kind} {repr(value)[:60]}; available: {', '.join(options)}"


def one_of(kind: str, options: tuple[str, ...]) -> BeforeValidator:
    """A pydantic validator for a name field: anything outside `options` is refused with the
    `unknown_name` message (put before the field's `Literal` check, whose message lists less)."""

    def check(value: object) -> object:
        if value not in options:
            raise ValueError(unknown_name(kind, value, options))
        return value

    return BeforeValidator(check)


SEED_LIMIT = 2**31 - 1
"""Seeds drawn from a generator lie in [0, SEED_LIMIT)."""


def child_seed(base: int, index: int) -> int:
    """The seed of the `index`-th member (episode, validation episode, evaluation stream) of
    something seeded `base`: `base + index`, so a run's episodes are reproducible one by one and
    do not depend on which process runs them."""
    return base + index


TRAINING_SEED_FLOOR = 10_000_000
"""The decision MDP's episodes (training and validation) draw their seeds from [this, SEED_LIMIT),
so no seed a run, a comparison or a report uses (below it) is ever trained or selected on."""


def drawn_seed(rng: np.random.Generator, low: int = 0) -> int:
    """A fresh seed in [low, SEED_LIMIT) drawn from a seeded generator (a gym env's `np_random`)."""
    return int(rng.integers(low, SEED_LIMIT))
