"""The environments a training run steps and their processes: the monitored decision MDP, its
worker processes, what ends them (SIGINT / SIGTERM with a checkpoint first, a dead worker) and
how they are closed."""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any

from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import SubprocVecEnv, VecEnv, VecEnvWrapper

from planner.model_file import CHECKPOINT
from stack.runtime.interrupts import handled_by, note_stop
from stack.settings.run import RunConfig
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.world_shards import ShardDied, ShardedWorlds, batched_training_env


class StopTraining(Exception):
    """Raised once a requested stop has its checkpoint written."""


STOPPING = "stopping: the checkpoint is written after the current step (further signals wait for it)"


@contextmanager
def stop_signals(handler: Callable[[int, Any], None]) -> Iterator[None]:
    """SIGINT and SIGTERM call `handler` inside the block (the command then exits 130, and says
    that it stops); only in the main thread, where Python delivers signals (a sweep's trial trains
    in a worker thread and Ray Tune stops it)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def noted(signum: int, frame: Any) -> None:
        note_stop()
        print(STOPPING, file=sys.stderr)
        handler(signum, frame)

    with handled_by(noted):
        yield


def monitored_env(config: RunConfig) -> Monitor:
    """The training env (SB3's `Monitor` keeps episode returns for the logs)."""
    return Monitor(HierarchicalHighwayEnv(config))


def training_env(config: RunConfig, ray: str | None = None) -> Monitor | VecEnv:
    """What a DDQN / DQN run steps: `train.worlds` batched worlds (in this process, or as
    `train.envs` shards in worker processes, or in Ray actors at the address `ray`), else one
    monitored env here or `train.envs` of them in worker processes."""
    if config.train.worlds is not None:
        return batched_training_env(config, ray)
    if config.train.envs == 1:
        return monitored_env(config)
    return SubprocVecEnv([partial(worker_env, config)] * config.train.envs)


def worker_env(config: RunConfig) -> Monitor:
    """The training env in a worker process, deaf to Ctrl-C: the learner stops the run (with a
    checkpoint) and closes the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return monitored_env(config)


class EnvWorkerDied(RuntimeError):
    """A training env worker process died; the message is one line for the user."""


def worker_death(env: object, out: Path, error: BaseException) -> str:
    """One line: that an env worker of `env` died (a shard that names itself: `ShardDied`), how,
    and what the run in `out` keeps."""
    kept = (
        f"its last checkpoint ({out / CHECKPOINT}) is kept: --resume {out} continues from it"
        if (out / CHECKPOINT).is_file()
        else "no checkpoint was written yet: start the run again"
    )
    if isinstance(error, ShardDied):
        return f"{error}; {kept}"
    codes = [p.exitcode for p in getattr(innermost(env), "processes", []) if p.exitcode not in (None, 0)]
    how = f" (exit code {codes[0]})" if codes else f" ({type(error).__name__})"
    return f"a training environment process died{how}; {kept}"


def close_env(env: Monitor | VecEnv, a_worker_died: bool = False) -> None:
    """Close `env` and its worker processes. After `a_worker_died` (or a close that finds one dead)
    the workers are ended without SB3's goodbye exchange: a reply of a live worker may already have
    been read while `waiting` is still set, and `close()` would wait for it forever."""
    inner = innermost(env)
    if not a_worker_died:
        try:
            env.close()
            return
        except (EOFError, OSError):
            pass
    if isinstance(inner, ShardedWorlds):
        inner.abandon()
        return
    for process in getattr(inner, "processes", []):
        process.kill()
        process.join(timeout=10)
    for remote in getattr(inner, "remotes", []):
        remote.close()
    if isinstance(inner, SubprocVecEnv):
        inner.closed = True


def innermost(env: object) -> object:
    """The vec env under `env`'s vec-env wrappers (SB3's `VecMonitor` of batched worlds), or `env`."""
    return env.unwrapped if isinstance(env, VecEnvWrapper) else env
