"""The model a training run builds and what it keeps of it: the SB3 (Double) DQN from the config,
the model it may start from, the callback that checkpoints it, the metadata every model file
carries."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from planner.ddqn import DoubleDQN
from planner.lane_network import LaneFeatures, LaneQNetwork
from planner.learned import LearnedAgent, load_agent
from planner.mobil import MobilPrior
from planner.model_metadata import ModelMetadata
from planner.networks import LANE_NETWORK, net_arch, network_kind
from records import N_ACTIONS, GridConfig
from stack.loop.closed_loop import grid_config
from stack.runs.model_fit import checked_start_model
from stack.settings.run import RunConfig
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.envs import StopTraining

ALGORITHMS: dict[str, type[DQN]] = {"ddqn": DoubleDQN, "dqn": DQN}


class Checkpoints(BaseCallback):
    """Checkpoints at a consistent point, the start of a rollout: every transition collected so
    far is in the buffer and every gradient step due is done, so a resumed run continues with the
    same counts as an uninterrupted one. `save()` whenever the steps pass a multiple of `every`
    (N environments advance N at a time), and when `stop_requested()` turns true: then the
    checkpoint is written and `StopTraining` raised."""

    def __init__(self, every: int, save: Callable[[], object], stop_requested: Callable[[], bool]) -> None:
        super().__init__()
        self.every, self.save, self.stop_requested = every, save, stop_requested
        self.done = 0

    def _on_training_start(self) -> None:
        self.done = self.num_timesteps // self.every

    def _on_rollout_start(self) -> None:
        self.num_timesteps = self.model.num_timesteps
        due = self.num_timesteps // self.every > self.done
        if due or self.stop_requested():
            self.done = self.num_timesteps // self.every
            self.save()
        if self.stop_requested():
            raise StopTraining

    def _on_step(self) -> bool:
        return True


def build_dqn(config: RunConfig, env: gym.Env | VecEnv, tensorboard: Path) -> DQN:
    """The SB3 model. Torch gets one thread: the Q-networks hold a few thousand weights, where
    more threads only add overhead and steal cores from the simulator (and one thread makes the
    result independent of the machine). With N environments or worlds each step of the vectorised
    env brings N transitions, and `train.replay_ratio` x N gradient steps follow it (1: the replay
    ratio of one env)."""
    th.set_num_threads(1)
    train = config.train
    algorithm = ALGORITHMS[train.algorithm]
    own_options: dict[str, Any] = {}
    if (demonstrations := train.demonstrations) is not None:
        own_options = {"demonstration_share": demonstrations.share, "margin": demonstrations.margin}
        own_options["margin_weight"] = demonstrations.margin_weight
    if train.mobil_prior:
        own_options["mobil_prior"] = MobilPrior(grid_config(config), train.mobil_prior)
    if train.action_mask:
        own_options["action_mask"] = True
    if train.overlap:
        own_options["overlap"] = True
    return algorithm(
        "MlpPolicy",
        env,
        learning_rate=train.learning_rate,
        buffer_size=train.buffer_size,
        learning_starts=train.learning_starts,
        batch_size=train.batch_size,
        gamma=train.gamma,
        n_steps=train.n_steps,
        train_freq=train.train_freq,
        gradient_steps=train.gradient_steps,
        target_update_interval=train.target_update_interval,
        exploration_fraction=train.exploration_fraction,
        exploration_initial_eps=train.exploration_initial_eps,
        exploration_final_eps=train.exploration_final_eps,
        policy_kwargs=policy_options(config),
        tensorboard_log=str(tensorboard),
        seed=config.seed,
        verbose=0,
        device="cpu",
        **own_options,
    )


def policy_options(config: RunConfig) -> dict[str, Any]:
    """SB3's `policy_kwargs`: the MLP's widths, and for the lane network its features extractor
    (`planner.lane_network`) on the run's grid, the widths then its head's."""
    options: dict[str, Any] = {"net_arch": net_arch(config.train.network)}
    if config.train.network == LANE_NETWORK:
        options |= lane_features_options(grid_config(config))
    return options


def lane_features_options(grid: GridConfig) -> dict[str, Any]:
    """SB3's `policy_kwargs` that make the lane network's features extractor read `grid`."""
    return {"features_extractor_class": LaneFeatures, "features_extractor_kwargs": {"grid": grid}}


def model_metadata(config: RunConfig, env: HierarchicalHighwayEnv, trained_steps: int) -> ModelMetadata:
    """What a model file of this run says about its model: algorithm, encoding, sizes, grid,
    training (its validation is added to the kept model's)."""
    train = config.train
    tabular = train.algorithm == "tabular"
    return ModelMetadata(
        kind="qtable" if tabular else network_kind(train.network),
        algorithm=train.algorithm,
        encoding=train.encoding,
        observation_size=int(np.prod(env.observation_space.shape)),
        actions=N_ACTIONS,
        hidden=() if tabular else tuple(net_arch(train.network)),
        network=train.network,
        grid=grid_config(config),
        lanes_count=config.highway.lanes_count,
        trained_steps=trained_steps,
        seed=config.seed,
        mobil_prior=train.mobil_prior,
        action_mask=train.action_mask,
    )


def initial_model(config: RunConfig) -> LearnedAgent | None:
    """The Q-network `train.init_model` names, checked against the run before any episode
    (`checked_start_model`); None without one."""
    if (path := checked_start_model(config)) is None:
        return None
    agent = load_agent(path, expected_algorithms=("ddqn", "dqn"))
    assert isinstance(agent, LearnedAgent), "DDQN / DQN files hold Q-networks"
    return agent


def warm_start(model: DQN, start: LearnedAgent, grid: GridConfig | None = None, lanes_count: int = 4) -> None:
    """Copy `start`'s Q-network into the online and target networks of `model`. A start that sees
    fewer of `grid`'s features than the run (so fewer observation values, on a road of
    `lanes_count` lanes) has its first layer widened: each input it knows keeps its weights, the new
    ones start at zero, so the model starts deciding as `start` does."""
    if isinstance(start.network, LaneQNetwork):
        with th.no_grad():
            for q_net in (model.policy.q_net, model.policy.q_net_target):
                q_net.features_extractor.load_state_dict(start.network.features.state_dict())
                q_net.q_net.load_state_dict(start.network.head.state_dict())
        return
    weights = start.network.state_dict()
    if weights["0.weight"].shape[1] != model.policy.q_net.q_net[0].in_features:
        assert grid is not None, "a start of another input size is widened onto the run's grid"
        weights = widened_first_layer(weights, start.grid_config, grid, lanes_count, start.sees_permitted)
    with th.no_grad():
        model.policy.q_net.q_net.load_state_dict(weights)
        model.policy.q_net_target.q_net.load_state_dict(weights)


def widened_first_layer(
    weights: dict[str, th.Tensor],
    start: GridConfig,
    grid: GridConfig,
    lanes_count: int,
    permitted: bool = False,
) -> dict[str, th.Tensor]:
    """`weights` of a Q-network seeing `start`'s observation, its first layer moved onto `grid`'s
    observation part by part (`GridConfig.observation_parts`), zero on the parts `start` does not
    have; the permitted commands that end both observations when `permitted` keep their weights."""
    first, parts = weights["0.weight"], grid.observation_parts(lanes_count)
    size = parts["lane"].stop
    widened = th.zeros((first.shape[0], size + N_ACTIONS * permitted))
    start_parts = start.observation_parts(lanes_count)
    for name, columns in parts.items():
        if name in start_parts:
            widened[:, columns] = first[:, start_parts[name]]
    if permitted:
        widened[:, size:] = first[:, -N_ACTIONS:]
    return {**weights, "0.weight": widened}
