"""Learned agents at inference: a Q-network (DQN / Double DQN) or a Q-table, loaded from a safe
model file, behind the same `predict` as every other agent."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch as th
from pydantic import ValidationError
from stable_baselines3 import DQN
from stable_baselines3.common.torch_layers import create_mlp
from torch import nn

from planner.agents import Action, Policy
from planner.model_file import ModelFileError, load_model, save_model
from planner.tabular import QLearning
from records import ENCODINGS, N_ACTIONS, Encoding, GridConfig


def q_network(observation_size: int, actions: int, hidden: list[int]) -> nn.Sequential:
    """The MLP of SB3's `QNetwork` (ReLU between linear layers), so weights move between them."""
    return nn.Sequential(*create_mlp(observation_size, actions, hidden))


class LearnedAgent(Policy):
    """Greedy agent over a Q-network; `grid_config` and `encoding` say what it must be shown."""

    def __init__(self, network: nn.Sequential, metadata: dict, source: str = "model") -> None:
        self.network = network.eval()
        self.metadata = metadata
        self.source = source
        self.observation_size = int(metadata["observation_size"])
        self.encoding: Encoding = metadata["encoding"]
        self.grid_config = GridConfig(**metadata["grid"])

    def q_values(self, observation: np.ndarray) -> np.ndarray:
        batch = np.asarray(observation, dtype=np.float32).reshape(-1, self.observation_size)
        with th.no_grad():
            return self.network(th.as_tensor(batch)).numpy()

    def choose(self, observation: np.ndarray) -> Action:
        size = np.asarray(observation).size
        if size % self.observation_size:
            raise ValueError(
                f"{self.source} expects observations of {self.observation_size} values "
                f"({self.encoding} encoding of grid {self.metadata['grid']}), got {size}"
            )
        actions = self.q_values(observation).argmax(axis=1)
        return actions[0] if np.asarray(observation).ndim == 1 else actions


class TabularAgent(Policy):
    """Greedy agent over a Q-table indexed by the tabular state [ego_lane, distances...]."""

    encoding: Encoding = "tabular"

    def __init__(self, table: np.ndarray, metadata: dict, source: str = "model") -> None:
        self.table = table
        self.metadata = metadata
        self.source = source
        self.grid_config = GridConfig(**metadata["grid"])

    def choose(self, observation: np.ndarray) -> Action:
        index = tuple(np.asarray(observation, dtype=np.int64).reshape(-1))
        if len(index) != self.table.ndim - 1 or any(
            not 0 <= i < n for i, n in zip(index, self.table.shape[:-1], strict=True)
        ):
            raise ValueError(
                f"{self.source} expects a tabular state of {self.table.ndim - 1} values within "
                f"{list(self.table.shape[:-1])}, got {list(index)}"
            )
        return np.int64(np.argmax(self.table[index]))


def export_q_network(model: DQN, path: Path | str, metadata: dict) -> Path:
    """Save an SB3 (Double) DQN's online Q-network weights with `metadata`."""
    state = model.policy.q_net.q_net.state_dict()
    return save_model(
        path, {k: v.detach().cpu().numpy() for k, v in state.items()}, {"kind": "mlp", **metadata}
    )


def save_q_table(agent: QLearning, path: Path | str, metadata: dict) -> Path:
    """Save a tabular Q-learner's table with `metadata`."""
    return save_model(path, {"q_table": agent.table}, {"kind": "qtable", **metadata})


MAX_INPUTS = 100_000
"""Largest observation a Q-network model may declare [values]."""
MAX_WIDTH, MAX_LAYERS = 4096, 8
"""Largest hidden layer [units] and number of hidden layers a model may declare."""


def load_agent(
    path: Path | str, expected_algorithms: tuple[str, ...] | None = None
) -> LearnedAgent | TabularAgent:
    """The agent stored in `path`. Its metadata is checked before anything is built: the kind,
    algorithm, encoding, grid and action count the loop can use, network sizes within bounds and
    the arrays' shapes equal to the ones those sizes give, every weight finite."""
    arrays, metadata = load_model(path)
    algorithm = metadata.get("algorithm")
    if expected_algorithms and algorithm not in expected_algorithms:
        raise ModelFileError(
            f"{path}: holds a {str(algorithm)[:40]!r} model; expected {' or '.join(expected_algorithms)}"
        )
    _check_metadata(path, metadata)
    for name, value in arrays.items():
        if not np.all(np.isfinite(value)):
            raise ModelFileError(f"{path}: array {name!r} holds NaN or infinite values")
    if metadata["kind"] == "qtable":
        table = arrays.get("q_table")
        if table is None or table.ndim < 2 or table.shape[-1] != N_ACTIONS or len(arrays) != 1:
            raise ModelFileError(
                f"{path}: expected one q_table array whose last axis has {N_ACTIONS} actions"
            )
        return TabularAgent(table.astype(np.float64), metadata, str(path))
    sizes = [int(metadata["observation_size"]), *map(int, metadata["hidden"]), N_ACTIONS]
    expected: dict[str, tuple[int, ...]] = {}
    for layer, (inputs, outputs) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        expected[f"{2 * layer}.weight"], expected[f"{2 * layer}.bias"] = (outputs, inputs), (outputs,)
    actual = {name: value.shape for name, value in arrays.items()}
    if actual != expected:
        raise ModelFileError(f"{path}: model arrays do not match its metadata (expected {expected})"[:300])
    network = q_network(sizes[0], N_ACTIONS, sizes[1:-1])
    network.load_state_dict({k: th.as_tensor(v, dtype=th.float32) for k, v in arrays.items()}, strict=True)
    return LearnedAgent(network, metadata, str(path))


def _check_metadata(path: Path | str, metadata: dict) -> None:
    """One line for the first metadata field the loop cannot use."""
    kind, encoding = metadata.get("kind"), metadata.get("encoding", "tabular")
    problem = None
    if kind not in ("mlp", "qtable"):
        problem = "kind: expected 'mlp' or 'qtable'"
    elif encoding not in ENCODINGS:
        problem = f"encoding: expected one of {', '.join(ENCODINGS)}"
    elif kind == "mlp":
        size, hidden, actions = (metadata.get(k) for k in ("observation_size", "hidden", "actions"))
        if not isinstance(size, int) or not 1 <= size <= MAX_INPUTS:
            problem = f"observation_size: expected an integer in 1..{MAX_INPUTS}"
        elif (
            not isinstance(hidden, list)
            or len(hidden) > MAX_LAYERS
            or not all(isinstance(width, int) and 1 <= width <= MAX_WIDTH for width in hidden)
        ):
            problem = f"hidden: expected at most {MAX_LAYERS} layer widths in 1..{MAX_WIDTH}"
        elif actions != N_ACTIONS:
            problem = f"actions: the loop commands LEFT, STAY, RIGHT ({N_ACTIONS}), not {str(actions)[:20]}"
    if problem is None:
        try:
            GridConfig.model_validate(metadata.get("grid"))
        except ValidationError as error:
            first = error.errors()[0]
            problem = f"grid.{'.'.join(map(str, first['loc']))}: {first['msg']}"[:200]
    if problem:
        raise ModelFileError(f"{path}: model metadata {problem}")
