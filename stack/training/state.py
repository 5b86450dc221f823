"""A training run's whole state as plain arrays and typed counters (`stack.training.checkpoint`),
for checkpoints a resumed run continues from exactly as if never stopped: online and target
Q-networks, Adam moments, the replay buffer, SB3's counters, the random generators and each env's
episode under way (replayed on resume: the simulator is deterministic)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecEnv

from planner.ddqn import Demonstrations, DoubleDQN
from planner.model_file import ExpectedArray
from planner.tabular import QLearning
from records import N_ACTIONS
from stack.training.batch_env import batched_worlds
from stack.training.checkpoint import DqnCounters, TabularCounters, generator_state
from stack.training.decision_env import EpisodeRecord

BUFFER_FIELDS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")
NUMPY_KEYS = ExpectedArray((624,), np.dtype(np.uint32))
"""numpy's global generator (MT19937) key, as `np.random.get_state` gives it."""

Layout = dict[str, tuple[ExpectedArray, ...]]
"""Array name -> what it may be (`planner.model_file.header_check`)."""


def dqn_state(model: DQN) -> tuple[dict[str, np.ndarray], DqnCounters]:
    """(arrays, counters) of `model`, for a safe model file: networks, optimizer, the replay
    buffer's filled rows (the rest are zeros, as in a new buffer: early in a run of a large buffer
    the checkpoint stays small), the demonstrations learnt from, the counters SB3 schedules by,
    numpy's global generator (exploration and replay sampling draw from it), the action space's
    generator (random actions before learning starts) and each env's episode under way."""
    arrays = {f"q/{k}": v.cpu().numpy() for k, v in model.policy.q_net.state_dict().items()}
    arrays |= {f"target/{k}": v.cpu().numpy() for k, v in model.policy.q_net_target.state_dict().items()}
    optimizer = model.policy.optimizer.state_dict()
    for index, state in optimizer["state"].items():
        for name, value in state.items():
            arrays[f"optimizer/{index}/{name}"] = th.as_tensor(value).cpu().numpy()
    buffer = model.replay_buffer
    assert buffer is not None, "SB3 builds the replay buffer with the model"
    filled = buffer.buffer_size if buffer.full else buffer.pos
    for name in BUFFER_FIELDS:
        arrays[f"buffer/{name}"] = getattr(buffer, name)[:filled]
    if isinstance(model, DoubleDQN) and model.demonstrations is not None:
        arrays |= {f"demonstrations/{k}": v for k, v in model.demonstrations.arrays().items()}
    _, arrays["random/numpy_keys"], *numpy_random = np.random.get_state()
    pending = model.pending_gradient_steps if isinstance(model, DoubleDQN) else 0
    env = model.get_env()
    assert env is not None, "a model in training has its env"
    counters = DqnCounters(
        num_timesteps=int(model.num_timesteps),
        n_updates=int(model._n_updates),
        n_calls=int(model._n_calls),
        episode_num=int(model._episode_num),
        exploration_rate=float(model.exploration_rate),
        buffer_pos=int(buffer.pos),
        buffer_full=bool(buffer.full),
        param_groups=optimizer["param_groups"],
        numpy_random=(int(numpy_random[0]), int(numpy_random[1]), float(numpy_random[2])),
        action_space_random=dict(model.action_space.np_random.bit_generator.state),
        episodes=episodes_under_way(env),
        pending_gradient_steps=pending or None,
    )
    return arrays, counters


def dqn_layout(model: DQN, demonstration_rows: int) -> Layout:
    """What a checkpoint of `model` (`dqn_state`) may hold, from the freshly built model, so a
    file that does not fit it is refused from its headers before anything large is read: both
    Q-networks exactly; the optimizer's state of parameter i shaped as it (Adam's moments) or a
    scalar (its step); at most the replay buffer's rows of each field; at most
    `demonstration_rows` demonstrations (a DoubleDQN's only); numpy's generator key."""
    layout: Layout = {}
    for prefix, network in (("q/", model.policy.q_net), ("target/", model.policy.q_net_target)):
        for name, value in network.state_dict().items():
            layout[prefix + name] = (ExpectedArray(tuple(value.shape), value.cpu().numpy().dtype),)
    parameters = [p for group in model.policy.optimizer.param_groups for p in group["params"]]
    for index, parameter in enumerate(parameters):
        like = ExpectedArray(tuple(parameter.shape), parameter.detach().cpu().numpy().dtype)
        layout[f"optimizer/{index}/*"] = (like, ExpectedArray(()))
    buffer = model.replay_buffer
    assert buffer is not None, "SB3 builds the replay buffer with the model"
    for name in BUFFER_FIELDS:
        field = getattr(buffer, name)
        layout[f"buffer/{name}"] = (ExpectedArray(field.shape, field.dtype, at_most_rows=True),)
    if isinstance(model, DoubleDQN) and demonstration_rows > 0:
        size = int(np.prod(model.observation_space.shape))  # type: ignore[arg-type]
        for demonstration in fields(Demonstrations):
            name = demonstration.name
            shape = (demonstration_rows, size) if "observations" in name else (demonstration_rows,)
            dtype = np.dtype(np.int64 if name == "actions" else np.float32)
            layout[f"demonstrations/{name}"] = (ExpectedArray(shape, dtype, at_most_rows=True),)
    layout["random/numpy_keys"] = (NUMPY_KEYS,)
    return layout


def restore_dqn_state(model: DQN, arrays: dict[str, np.ndarray], counters: DqnCounters) -> BaseCallback:
    """Put the state `dqn_state` saved back into `model`. What SB3 resets when training starts (the
    episodes under way, the generators) is put back by the returned callback's training start.
    Raises KeyError / ValueError / TypeError / RuntimeError when the state does not fit `model`."""
    model.policy.q_net.load_state_dict(_prefixed(arrays, "q/"))
    model.policy.q_net_target.load_state_dict(_prefixed(arrays, "target/"))
    state: dict[int, dict] = {}
    for key, value in _prefixed(arrays, "optimizer/").items():
        index, name = key.split("/")
        state.setdefault(int(index), {})[name] = value
    model.policy.optimizer.load_state_dict({"state": state, "param_groups": counters.param_groups})
    buffer = model.replay_buffer
    assert buffer is not None, "SB3 builds the replay buffer with the model"
    for name, value in _prefixed(arrays, "buffer/").items():
        getattr(buffer, name)[: len(value)] = value.numpy()
    buffer.pos, buffer.full = counters.buffer_pos, counters.buffer_full
    model.num_timesteps, model._n_updates = counters.num_timesteps, counters.n_updates
    model._episode_num = counters.episode_num
    model._n_calls = counters.n_calls or 0
    if isinstance(model, DoubleDQN):
        model.pending_gradient_steps = counters.pending_gradient_steps or 0
    if counters.exploration_rate is not None:
        model.exploration_rate = counters.exploration_rate
    if isinstance(model, DoubleDQN) and (demonstrations := _prefixed(arrays, "demonstrations/")):
        size = int(np.prod(model.observation_space.shape))  # type: ignore[arg-type]
        model.demonstrations = Demonstrations.from_arrays(
            {k: v.numpy() for k, v in demonstrations.items()}, size, N_ACTIONS
        )
    return ContinueEpisodes(arrays, counters, model.n_envs)


class ContinueEpisodes(BaseCallback):
    """At training start, after SB3 has reset the envs: replays each env's episode under way and
    puts the generators back, so the resumed run continues the interrupted one transition for
    transition. A checkpoint without them (written by an older drivestack) resumes with fresh
    episodes."""

    def __init__(self, arrays: dict[str, np.ndarray], counters: DqnCounters, n_envs: int) -> None:
        super().__init__()
        self.exact = counters.episodes is not None
        if counters.episodes is None:
            return
        self.episodes = counters.episodes
        if len(self.episodes) != n_envs:
            raise ValueError(f"{len(self.episodes)} episodes under way for {n_envs} envs")
        if counters.numpy_random is None or counters.action_space_random is None:
            raise ValueError("episodes under way without the generators to replay them")
        self.numpy_random = ("MT19937", arrays["random/numpy_keys"], *counters.numpy_random)
        np.random.RandomState().set_state(self.numpy_random)
        self.action_space_random = generator_state(counters.action_space_random)

    def _on_training_start(self) -> None:
        if not self.exact:
            return
        env = self.model.get_env()
        assert env is not None, "a model in training has its env"
        if (worlds := batched_worlds(env)) is not None:
            self.model._last_obs = worlds.replay(self.episodes)
        else:
            observations = [
                env.env_method("replay_episode", record, indices=[index])[0]
                for index, record in enumerate(self.episodes)
            ]
            self.model._last_obs = np.stack(observations)
        self.model._last_episode_starts = np.array([not record.actions for record in self.episodes])
        np.random.set_state(self.numpy_random)
        self.model.action_space.np_random.bit_generator.state = self.action_space_random

    def _on_step(self) -> bool:
        return True


def episodes_under_way(env: VecEnv) -> tuple[EpisodeRecord, ...]:
    """Each env's (or batched world's) episode under way."""
    if (worlds := batched_worlds(env)) is not None:
        return worlds.episode_records()
    return tuple(env.env_method("episode_record"))


def tabular_state(model: QLearning, env: Monitor) -> tuple[dict[str, np.ndarray], TabularCounters]:
    """(arrays, counters) of a tabular learner: its table, steps, generator and episode under way."""
    episode = env.unwrapped.episode_record()  # type: ignore[attr-defined]
    counters = TabularCounters(
        num_timesteps=model.steps, tabular_random=dict(model.rng.bit_generator.state), episodes=(episode,)
    )
    return {"q_table": model.table}, counters


def tabular_layout(model: QLearning) -> Layout:
    """What a checkpoint of `model` (`tabular_state`) holds: its table, exactly."""
    return {"q_table": (ExpectedArray(model.table.shape, model.table.dtype),)}


def restore_tabular_state(
    model: QLearning, env: Monitor, arrays: dict[str, np.ndarray], counters: TabularCounters
) -> np.ndarray | None:
    """Put `tabular_state` back into `model` and `env`; the observation to continue from (None for
    a checkpoint of an older drivestack, which continues with a fresh episode). Raises KeyError /
    ValueError / TypeError when the checkpoint does not fit."""
    if arrays.get("q_table", np.empty(0)).shape != model.table.shape:
        raise ValueError("its q_table does not fit this run's table")
    model.table[...] = arrays["q_table"]
    model.steps = counters.num_timesteps
    if counters.episodes is None:
        return None
    (episode,) = counters.episodes
    if counters.tabular_random is None:
        raise ValueError("an episode under way without the generator to replay it")
    model.rng.bit_generator.state = counters.tabular_random
    env.reset()
    return env.unwrapped.replay_episode(episode)  # type: ignore[attr-defined]


def _prefixed(arrays: dict[str, np.ndarray], prefix: str) -> dict[str, th.Tensor]:
    return {k.removeprefix(prefix): th.as_tensor(v) for k, v in arrays.items() if k.startswith(prefix)}
