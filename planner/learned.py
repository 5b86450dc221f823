"""Learned agents at inference: a Q-network (DQN / Double DQN) or a Q-table, loaded from a safe
model file, behind the same `predict` as every other agent."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.torch_layers import create_mlp
from torch import nn

from planner.agents import Action, Policy
from planner.lane_network import LaneFeatures, LaneQNetwork
from planner.mobil import MobilPrior
from planner.model_check import checked_model
from planner.model_file import ModelFileError, save_model
from planner.model_metadata import ModelKind, ModelMetadata
from planner.networks import MAX_MEMBERS, ensemble_named, member_prefix
from planner.tabular import QLearning
from records import N_ACTIONS, Command, Encoding, GridConfig

_CHANGES = np.arange(N_ACTIONS) != Command.STAY
"""The commands that change lane."""


def q_network(observation_size: int, actions: int, hidden: list[int]) -> nn.Sequential:
    """The MLP of SB3's `QNetwork` (ReLU between linear layers), so weights move between them."""
    return nn.Sequential(*create_mlp(observation_size, actions, hidden))


class MeanQNetwork(nn.Module):
    """An ensemble's Q-values: the mean of its members', networks of one shape trained apart (other
    seeds). Where lanes are alike, one network's Q-values for a change and for STAY differ by less
    than their error, and its greedy choice follows that error; the members' errors differ, so
    their mean changes lane only where they agree the change pays."""

    def __init__(self, members: list[nn.Module]) -> None:
        super().__init__()
        self.members = nn.ModuleList(members)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.member_values(observations).mean(dim=0)

    def member_values(self, observations: th.Tensor) -> th.Tensor:
        """(members, batch, actions): each member's Q-values."""
        return th.stack([member(observations) for member in self.members])


class LearnedAgent(Policy):
    """Greedy agent over a Q-network (with the MOBIL prior its file declares); `grid_config` and
    `encoding` say what it must be shown, and `sees_permitted` whether the loop appends the safety
    layer's permitted commands to it (a model trained with an action mask): it then decides among
    them. A lane change must beat STAY's Q-value by `change_margin` (None: the margin calibrated
    into its model file, else 0; `economical_choice`): a hysteresis, so near-ties between lanes the
    network rates alike keep the lane instead of swinging between them."""

    def __init__(
        self,
        network: nn.Module,
        metadata: ModelMetadata,
        source: str = "model",
        change_margin: float | None = None,
    ) -> None:
        assert metadata.observation_size is not None, "a Q-network's metadata names its input size"
        self.network = network.eval()
        self.metadata = metadata
        self.source = source
        self.observation_size = metadata.observation_size
        self.encoding: Encoding = metadata.encoding
        self.grid_config: GridConfig = metadata.grid
        self.prior = MobilPrior(metadata.grid, metadata.mobil_prior) if metadata.mobil_prior else None
        self.sees_permitted = metadata.action_mask
        self.change_margin = change_margin if change_margin is not None else metadata.change_margin or 0.0
        self.last_rated: tuple[np.ndarray | None, np.ndarray] = (None, np.zeros((1, N_ACTIONS)))
        """The last observation decided on and its `rated` values (`scores` reads them)."""

    def q_values(self, observation: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return self.network(self._batch(observation)).numpy()

    def member_q_values(self, observation: np.ndarray) -> np.ndarray:
        """(members, batch, actions): each member's Q-values (one member: the network's)."""
        with th.no_grad():
            return self._member_values(self._batch(observation)).numpy()

    def _batch(self, observation: np.ndarray) -> th.Tensor:
        return th.as_tensor(np.asarray(observation, dtype=np.float32).reshape(-1, self.observation_size))

    def _member_values(self, batch: th.Tensor) -> th.Tensor:
        if isinstance(self.network, MeanQNetwork):
            return self.network.member_values(batch)
        return self.network(batch)[None]

    score_name = "Q-value (with the MOBIL prior's bonus)"

    def scores(self, observation: np.ndarray) -> np.ndarray:
        """The Q-values the greedy decision on one `observation` compares, per `Command` (those of
        the last decision when it was on this very observation: no second pass of the network)."""
        seen, rated = self.last_rated
        return np.asarray((rated if seen is observation else self.rated(observation))[0], dtype=float)

    def rated(self, observation: np.ndarray) -> np.ndarray:
        """(batch, actions): the Q-values with the MOBIL prior's bonus, checked for size."""
        self._check_size(observation)
        return self._with_prior(observation, self.q_values(observation))

    def _check_size(self, observation: np.ndarray) -> None:
        size = np.asarray(observation).size
        if size % self.observation_size:
            raise ValueError(
                f"{self.source} expects observations of {self.observation_size} values "
                f"({self.encoding} encoding of grid {self.grid_config.model_dump(mode='json')}), "
                f"got {size}"
            )

    def _with_prior(self, observation: np.ndarray, q_values: np.ndarray) -> np.ndarray:
        if self.prior is not None:
            q_values += self.prior.bonuses(np.asarray(observation).reshape(len(q_values), -1))
        return q_values

    def choose(self, observation: np.ndarray) -> Action:
        return self._greedy(observation, self.rated(observation))

    def choose_with_members(self, observation: np.ndarray) -> tuple[Action, np.ndarray]:
        """`choose(observation)` and the members' Q-values (members, batch, actions) it came from,
        from one pass of the members (their mean taken as the ensemble's network takes it)."""
        self._check_size(observation)
        with th.no_grad():
            members = self._member_values(self._batch(observation))
            q_values = members.mean(dim=0).numpy()
        return self._greedy(observation, self._with_prior(observation, q_values)), members.numpy()

    def _greedy(self, observation: np.ndarray, q_values: np.ndarray) -> Action:
        """The greedy command of each row of rated `q_values`, among the permitted ones."""
        self.last_rated = (observation, q_values)
        permitted = None
        if self.sees_permitted:
            permitted = np.asarray(observation).reshape(len(q_values), -1)[:, -N_ACTIONS:] >= 0.5
        actions = economical_choice(q_values, permitted, self.change_margin)
        return actions[0] if np.asarray(observation).ndim == 1 else actions


def economical_choice(q_values: np.ndarray, permitted: np.ndarray | None, change_margin: float) -> np.ndarray:
    """(batch,) the command of each row of `q_values` (batch, actions), among the `permitted` ones
    (None: all), where a lane change must beat STAY's Q-value by at least `change_margin`
    [Q-value]: the one decision law of every learned agent, whether it decides for one world or
    for a batch (0: the plain argmax, which takes LEFT on a tie with STAY)."""
    if permitted is not None:
        q_values = np.where(permitted, q_values, -np.inf)
    return np.asarray((q_values - change_margin * _CHANGES).argmax(axis=1))


class TabularAgent(Policy):
    """Greedy agent over a Q-table indexed by the tabular state [ego_lane, distances...]."""

    encoding: Encoding = "tabular"

    def __init__(self, table: np.ndarray, metadata: ModelMetadata, source: str = "model") -> None:
        self.table = table
        self.metadata = metadata
        self.source = source
        self.grid_config: GridConfig = metadata.grid

    score_name = "Q-value (table)"

    def scores(self, observation: np.ndarray) -> np.ndarray:
        """The table's Q-values for one tabular state, per `Command` (checked as `choose` does)."""
        self.choose(observation)
        return np.asarray(self.table[tuple(np.asarray(observation, dtype=np.int64).reshape(-1))], dtype=float)

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


def export_q_network(model: DQN, path: Path | str, metadata: ModelMetadata) -> Path:
    """Save an SB3 (Double) DQN's online Q-network weights with `metadata`: of kind `mlp` (the
    MLP's `0.weight`, ...), or `lane-mlp` for a lane network (its `features.*` and `head.*`)."""
    q_net = model.policy.q_net
    kind: ModelKind = "mlp"
    parts: dict[str, nn.Module] = {"": q_net.q_net}
    if isinstance(q_net.features_extractor, LaneFeatures):
        kind, parts = "lane-mlp", {"features.": q_net.features_extractor, "head.": q_net.q_net}
    weights = {
        prefix + name: value.detach().cpu().numpy()
        for prefix, part in parts.items()
        for name, value in part.state_dict().items()
    }
    return save_model(path, weights, replace(metadata, kind=kind).to_json())


def save_q_table(agent: QLearning, path: Path | str, metadata: ModelMetadata) -> Path:
    """Save a tabular Q-learner's table with `metadata` (of kind `qtable`)."""
    return save_model(path, {"q_table": agent.table}, replace(metadata, kind="qtable").to_json())


def load_agent(
    path: Path | str, expected_algorithms: tuple[str, ...] | None = None, change_margin: float | None = None
) -> LearnedAgent | TabularAgent:
    """The agent stored in `path` (a Q-network decides with the hysteresis `change_margin`; None:
    the one calibrated into the file, else 0). Its metadata is checked before anything is built:
    the kind, algorithm, encoding, grid and action count the loop can use, network sizes within
    bounds and the arrays' shapes equal to the ones those sizes give, every weight finite."""
    arrays, metadata = checked_model(path, expected_algorithms)
    if metadata.kind == "qtable":
        return TabularAgent(arrays["q_table"].astype(np.float64), metadata, str(path))
    networks = [
        _q_network(metadata, _member_arrays(arrays, index, metadata.members))
        for index in range(metadata.members)
    ]
    network = networks[0] if len(networks) == 1 else MeanQNetwork(networks)
    return LearnedAgent(network, metadata, str(path), change_margin)


def _q_network(metadata: ModelMetadata, arrays: dict[str, np.ndarray]) -> nn.Module:
    """The Q-network of `metadata`'s kind and sizes holding `arrays` (checked by `checked_model`)."""
    assert metadata.observation_size is not None, "checked_model checks a Q-network's input size"
    network: nn.Module
    if metadata.kind == "lane-mlp":
        network = LaneQNetwork(metadata.grid, metadata.observation_size, list(metadata.hidden))
    else:
        network = q_network(metadata.observation_size, N_ACTIONS, list(metadata.hidden))
    network.load_state_dict({k: th.as_tensor(v, dtype=th.float32) for k, v in arrays.items()}, strict=True)
    return network


def _member_arrays(arrays: dict[str, np.ndarray], index: int, members: int) -> dict[str, np.ndarray]:
    """The arrays of an ensemble's member `index`, named as one network's."""
    if members == 1:
        return arrays
    prefix = member_prefix(index)
    return {name.removeprefix(prefix): value for name, value in arrays.items() if name.startswith(prefix)}


_MUST_AGREE = (
    "kind",
    "algorithm",
    "encoding",
    "observation_size",
    "hidden",
    "grid",
    "mobil_prior",
    "action_mask",
)
"""What every member of an ensemble shares: one observation, one network shape, one decision rule."""


def save_ensemble(paths: list[Path], out: Path) -> Path:
    """Write the DDQN / DQN model files `paths` (2 to MAX_MEMBERS single networks, trained apart)
    as one ensemble model file at `out`, deciding on the mean of their Q-values (`MeanQNetwork`).
    A file that cannot load, is a Q-table or an ensemble, or differs from the first in what
    `_MUST_AGREE` names is refused (ModelFileError, one line) before anything is written."""
    if not 2 <= len(paths) <= MAX_MEMBERS:
        raise ModelFileError(f"an ensemble takes 2 to {MAX_MEMBERS} model files, not {len(paths)}")
    members = [checked_model(path, ("ddqn", "dqn")) for path in paths]
    first = members[0][1]
    for path, (_, metadata) in zip(paths, members, strict=True):
        if metadata.members != 1:
            raise ModelFileError(f"{path}: already an ensemble of {metadata.members}; give its members")
        for field in _MUST_AGREE:
            if (theirs := getattr(metadata, field)) != (ours := getattr(first, field)):
                raise ModelFileError(f"{path}: {field} {theirs} differs from {paths[0]}'s {ours}"[:300])
    arrays = ensemble_named([found for found, _ in members])
    steps = [metadata.trained_steps for _, metadata in members if metadata.trained_steps is not None]
    seeds = tuple(metadata.seed for _, metadata in members if metadata.seed is not None)
    metadata = replace(
        first, members=len(paths), seed=None, validation=None,
        trained_steps=sum(steps) if len(steps) == len(members) else None,
        member_seeds=seeds if len(seeds) == len(members) else (),
    )  # fmt: skip
    return save_model(out, arrays, metadata.to_json())
