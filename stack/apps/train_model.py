"""The model a training run builds and what it keeps of it: the env and the SB3 (Double) DQN from
the config, a callback for periodic work, the metadata every model file carries, the model's whole
state as plain arrays for checkpoints (online and target Q-networks, Adam moments, the replay
buffer, plus JSON counters) so `--resume` continues exactly, and the training curve."""

from __future__ import annotations

import json
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecEnv

from perception.grid import OccupancyGridBuilder
from planner.ddqn import DoubleDQN
from planner.networks import net_arch
from planner.validation import Validation, kept_models
from records import N_ACTIONS
from stack.core.closed_loop import grid_config
from stack.core.config import RunConfig
from stack.core.decision_env import HierarchicalHighwayEnv

ALGORITHMS: dict[str, type[DQN]] = {"ddqn": DoubleDQN, "dqn": DQN}
BUFFER_FIELDS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


class StopTraining(Exception):
    """Raised once a requested stop has its checkpoint written."""


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


@contextmanager
def stop_signals(handler: Callable[[int, Any], None]) -> Iterator[None]:
    """SIGINT and SIGTERM call `handler` inside the block; only in the main thread, where Python
    delivers signals (a sweep's trial trains in a worker thread and Ray Tune stops it)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def monitored_env(config: RunConfig) -> Monitor:
    """The training env (SB3's `Monitor` keeps episode returns for the logs)."""
    return Monitor(HierarchicalHighwayEnv(config))


def worker_env(config: RunConfig) -> Monitor:
    """The training env in a worker process, deaf to Ctrl-C: the learner stops the run (with a
    checkpoint) and closes the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return monitored_env(config)


def replay_buffer_bytes(config: RunConfig) -> int:
    """Memory SB3's replay buffer takes for `config` [bytes]: observations and next observations
    (float32) plus action, reward, done and timeout per transition."""
    grid = OccupancyGridBuilder(grid_config(config))
    size = int(np.prod(grid.space(config.train.encoding, config.highway.lanes_count).shape))
    return config.train.buffer_size * (2 * 4 * size + 8 + 4 + 4 + 4)


def available_memory_bytes() -> int | None:
    """MemAvailable of /proc/meminfo [bytes]; None where it cannot be read."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def build_dqn(config: RunConfig, env: gym.Env | VecEnv, tensorboard: Path) -> DQN:
    """The SB3 model. Torch gets one thread: the Q-networks hold a few thousand weights, where
    more threads only add overhead and steal cores from the simulator (and one thread makes the
    result independent of the machine). With N environments each step of the vectorised env
    brings N transitions, so N gradient steps follow it: the replay ratio stays that of one env."""
    th.set_num_threads(1)
    train = config.train
    algorithm = ALGORITHMS[train.algorithm]

    return algorithm(
        "MlpPolicy",
        env,
        learning_rate=train.learning_rate,
        buffer_size=train.buffer_size,
        learning_starts=train.learning_starts,
        batch_size=train.batch_size,
        gamma=train.gamma,
        train_freq=train.train_freq,
        gradient_steps=train.envs,
        target_update_interval=train.target_update_interval,
        exploration_fraction=train.exploration_fraction,
        exploration_final_eps=train.exploration_final_eps,
        policy_kwargs={"net_arch": net_arch(train.network)},
        tensorboard_log=str(tensorboard),
        seed=config.seed,
        verbose=0,
        device="cpu",
    )


def model_metadata(config: RunConfig, env: HierarchicalHighwayEnv, trained_steps: int) -> dict:
    """What a model file says about the model: algorithm, encoding, sizes, grid, training."""
    train = config.train
    return {
        "algorithm": train.algorithm,
        "encoding": train.encoding,
        "observation_size": int(np.prod(env.observation_space.shape)),
        "actions": N_ACTIONS,
        "hidden": net_arch(train.network) if train.algorithm != "tabular" else [],
        "network": train.network,
        "grid": grid_config(config).model_dump(mode="json"),
        "lanes_count": config.highway.lanes_count,
        "trained_steps": trained_steps,
        "seed": config.seed,
    }


def dqn_state(model: DQN) -> tuple[dict[str, np.ndarray], dict]:
    """(arrays, counters) of `model`, for a safe model file."""
    arrays = {f"q/{k}": v.cpu().numpy() for k, v in model.policy.q_net.state_dict().items()}
    arrays |= {f"target/{k}": v.cpu().numpy() for k, v in model.policy.q_net_target.state_dict().items()}
    optimizer = model.policy.optimizer.state_dict()
    for index, state in optimizer["state"].items():
        for name, value in state.items():
            arrays[f"optimizer/{index}/{name}"] = th.as_tensor(value).cpu().numpy()
    buffer = model.replay_buffer
    assert buffer is not None, "SB3 builds the replay buffer with the model"
    for name in BUFFER_FIELDS:
        arrays[f"buffer/{name}"] = getattr(buffer, name)
    counters = {
        "num_timesteps": int(model.num_timesteps),
        "n_updates": int(model._n_updates),
        "episode_num": int(model._episode_num),
        "buffer_pos": int(buffer.pos),
        "buffer_full": bool(buffer.full),
        "param_groups": optimizer["param_groups"],
    }
    return arrays, counters


def restore_dqn_state(model: DQN, arrays: dict[str, np.ndarray], counters: dict) -> None:
    """Put the state `dqn_state` saved back into `model`."""
    model.policy.q_net.load_state_dict(_prefixed(arrays, "q/"))
    model.policy.q_net_target.load_state_dict(_prefixed(arrays, "target/"))
    state: dict[int, dict] = {}
    for key, value in _prefixed(arrays, "optimizer/").items():
        index, name = key.split("/")
        state.setdefault(int(index), {})[name] = value
    model.policy.optimizer.load_state_dict({"state": state, "param_groups": counters["param_groups"]})
    buffer = model.replay_buffer
    assert buffer is not None, "SB3 builds the replay buffer with the model"
    for name, value in _prefixed(arrays, "buffer/").items():
        getattr(buffer, name)[...] = value.numpy()
    buffer.pos, buffer.full = counters["buffer_pos"], counters["buffer_full"]
    model.num_timesteps, model._n_updates = counters["num_timesteps"], counters["n_updates"]
    model._episode_num = counters["episode_num"]


def _prefixed(arrays: dict[str, np.ndarray], prefix: str) -> dict[str, th.Tensor]:
    return {k.removeprefix(prefix): th.as_tensor(v) for k, v in arrays.items() if k.startswith(prefix)}


def plot_training_curve(history: list[Validation], path: Path) -> None:
    """Mean validation return and collision rate against training steps."""
    figure, (returns, collisions) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for period, marker in (("short", "o"), ("long", "s")):
        points = [v for v in history if v.period == period]
        returns.plot(
            [v.step for v in points], [v.mean_return for v in points], marker, label=f"{period} validation"
        )
        collisions.plot([v.step for v in points], [100 * v.collision_rate for v in points], marker)
    best = kept_models(history)
    returns.plot(
        [v.step for v in best], [v.mean_return for v in best], "k*", markersize=10, label="kept (best)"
    )
    returns.set_ylabel("mean return")
    collisions.set_ylabel("collision rate [%]")
    collisions.set_xlabel("training steps")
    returns.legend(fontsize="small")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def write_training_summary(
    config: RunConfig, out: Path, history: list[Validation], run: dict, best: Path
) -> dict:
    """`summary.json` (the run's `steps`, `wall_time_s`, `interrupted`, the best validation and
    model), `validation.json` and `training_curve.png` in `out`; returns the summary."""
    if history:
        plot_training_curve(history, out / "training_curve.png")
    kept = kept_models(history)
    summary = {
        "algorithm": config.train.algorithm,
        "network": config.train.network,
        "target_steps": config.train.steps,
        **run,
        "best_validation": kept[-1].__dict__ if kept else None,
        "validations": len(history),
        "best_model": str(best) if best.is_file() else None,
        "training_curve": "training_curve.png" if history else "not drawn: no validation ran yet",
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "validation.json").write_text(json.dumps([v.__dict__ for v in history], indent=2) + "\n")
    return summary
