"""The batched training env over several processes (`train.worlds` N with `train.envs` P): the N
worlds stepped as P shards of N/P, each a `TrainingWorlds` in a worker process, behind one SB3
`VecEnv` in the learner's process (SB3's `SubprocVecEnv` pattern: one pipe per worker). A step
hands every shard its slice of the actions at once and waits for all of them. World k of the
shards is world k of the one-process env: each shard gets its slice of the seeds (world k's
generator seeded `seed + k`), the actions and the episode records, and their answers are
concatenated in world order, so a run is bit for bit the one of `train.envs: 1`."""

from __future__ import annotations

import multiprocessing as mp
import signal
from abc import ABC, abstractmethod
from collections.abc import Sequence
from multiprocessing.connection import Connection
from multiprocessing.context import BaseContext
from multiprocessing.process import BaseProcess
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecMonitor
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from records import N_ACTIONS
from stack.settings.run import RunConfig
from stack.training.batch_env import ReplayableWorlds, TrainingWorlds
from stack.training.decision_batch import batch_config
from stack.training.decision_env import EpisodeRecord
from stack.training.gym_vector_env import WorldsVecEnv


def shard_worker(remote: Connection, learner_end: Connection, config: RunConfig, worlds: int) -> None:
    """A shard's process: `worlds` worlds of `config` answering the learner's requests on `remote`
    until it says `close` or its end of the pipe closes. Deaf to Ctrl-C, as the per-world workers:
    the learner stops the run (with a checkpoint, which asks the shards for their episodes) and
    closes the shards itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    learner_end.close()
    shard = TrainingWorlds(config, worlds)
    try:
        while True:
            try:
                request, data = remote.recv()
            except EOFError:
                break
            if request == "close":
                break
            remote.send(answer(shard, request, data))
    finally:
        shard.close()
        remote.close()


def answer(shard: TrainingWorlds, request: str, data: Any) -> Any:
    """What `shard` answers to the learner's `request` (with its `data`)."""
    if request == "step":
        shard.step_async(data)
        return shard.step_wait()
    if request == "reset":
        shard.worlds.seed(list(data))
        return shard.reset()
    if request == "episode_records":
        return shard.episode_records()
    if request == "replay":
        return shard.replay(data)
    if request == "observation_space":
        return shard.observation_space
    raise ValueError(f"a shard of worlds does not answer {request!r}")


class ShardDied(ConnectionError):
    """A shard of worlds died under the learner; the message names it and how, in one line."""


class ShardedWorlds(WorldsVecEnv, ReplayableWorlds, ABC):
    """`worlds` worlds split into equal shards, world k in shard k // (worlds / shards), each a
    `TrainingWorlds` elsewhere answering `answer`'s requests: what the learner asks of them, in
    world order, whatever carries the requests (`_send`, `_receive`)."""

    render_mode = None

    def __init__(self, worlds: int, shards: int) -> None:
        if shards < 1 or worlds % shards:
            raise ValueError(f"{worlds} worlds do not split evenly over {shards} processes")
        size = worlds // shards
        self.parts = [slice(first, first + size) for first in range(0, worlds, size)]
        self.waiting = self.closed = False

    def _start(self, observation_space: spaces.Box) -> None:
        """Once the shards run: the vec env's spaces (every shard has the first one's)."""
        super().__init__(self.parts[-1].stop, observation_space, spaces.Discrete(N_ACTIONS))

    @abstractmethod
    def _send(self, shard: int, request: str, data: Any) -> None:
        """Hand `request` (with its `data`) to shard `shard`, without waiting for its answer."""

    @abstractmethod
    def _receive(self, shard: int) -> Any:
        """Shard `shard`'s answer to the request it was last handed."""

    @abstractmethod
    def abandon(self) -> None:
        """End the shards at once, without reading what they may still be answering (after one
        died, a live one's answer may already have been read)."""

    def _ask(self, request: str, data: Sequence[Any]) -> list[Any]:
        """Every shard's answer to `request`, shard i sent `data[i]`: all sent before any is read,
        so the shards work at once."""
        for shard, part in enumerate(data):
            self._send(shard, request, part)
        return [self._receive(shard) for shard in range(len(self.parts))]

    def reset(self) -> np.ndarray:
        observations = self._ask("reset", [self._seeds[part] for part in self.parts])
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return np.concatenate(observations)

    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)
        for shard, part in enumerate(self.parts):
            self._send(shard, "step", actions[part])
        self.waiting = True

    def step_wait(self) -> VecEnvStepReturn:
        results = [self._receive(shard) for shard in range(len(self.parts))]
        self.waiting = False
        observations, rewards, dones, infos = zip(*results, strict=True)
        every_info = [info for shard in infos for info in shard]
        return np.concatenate(observations), np.concatenate(rewards), np.concatenate(dones), every_info

    def episode_records(self) -> tuple[EpisodeRecord, ...]:
        """Each world's episode under way, gathered from the shards in world order."""
        shards = self._ask("episode_records", [None] * len(self.parts))
        return tuple(record for shard in shards for record in shard)

    def replay(self, records: Sequence[EpisodeRecord]) -> np.ndarray:
        """Each shard rebuilds its worlds' episodes of `records` (`TrainingWorlds.replay`), all at
        once: the observations."""
        if len(records) != self.num_envs:
            raise ValueError(f"{len(records)} episodes under way for {self.num_envs} worlds")
        return np.concatenate(self._ask("replay", [list(records[part]) for part in self.parts]))


class WorldShards(ShardedWorlds):
    """`worlds` worlds of `config` in `shards` worker processes of `worlds / shards` worlds each;
    `processes`, `remotes` and `closed` as SB3's `SubprocVecEnv` has them, so a dead worker is
    found and ended as one of its workers is."""

    def __init__(self, config: RunConfig, worlds: int, shards: int, start_method: str | None = None) -> None:
        super().__init__(worlds, shards)
        batch_config(config)
        size = worlds // shards
        context = shard_context(start_method)
        self.remotes: list[Connection] = []
        self.processes: list[BaseProcess] = []
        for _ in range(shards):
            remote, worker_end = context.Pipe()
            process = context.Process(  # type: ignore[attr-defined]
                target=shard_worker, args=(worker_end, remote, config, size), daemon=True
            )
            process.start()
            worker_end.close()
            self.remotes.append(remote)
            self.processes.append(process)
        self.remotes[0].send(("observation_space", None))
        self._start(self.remotes[0].recv())

    def _send(self, shard: int, request: str, data: Any) -> None:
        self.remotes[shard].send((request, data))

    def _receive(self, shard: int) -> Any:
        return self.remotes[shard].recv()

    def close(self) -> None:
        """End the shards: a step under way is read first, then each is told to close and joined."""
        if self.closed:
            return
        if self.waiting:
            for remote in self.remotes:
                remote.recv()
        for remote in self.remotes:
            remote.send(("close", None))
        for process in self.processes:
            process.join()
        for remote in self.remotes:
            remote.close()
        self.closed = True

    def abandon(self) -> None:
        for process in self.processes:
            process.kill()
            process.join(timeout=10)
        for remote in self.remotes:
            remote.close()
        self.closed = True


def shard_context(start_method: str | None = None) -> BaseContext:
    """The processes' start method: `start_method`, else SB3's `SubprocVecEnv` default, which the
    per-world workers use (forkserver where there is one: fork is not safe beside torch's threads;
    else spawn). A forkserver not yet started imports the shards' modules (the simulator, SB3,
    torch: ~3 CPU-s) once, before it forks the shards, instead of each shard importing them."""
    method = start_method or ("forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn")
    context = mp.get_context(method)
    if method == "forkserver":
        context.set_forkserver_preload(["__main__", __name__])
    return context


def batched_training_env(config: RunConfig, ray: str | None = None) -> VecMonitor:
    """`train.worlds` worlds of `config`, each episode of a `train.scenarios` mix drawing its
    member as the per-world env does: in this process, as `train.envs` shards in worker
    processes, or with `ray` (an address: `local`, `auto`, HOST:PORT) as `train.envs` shards in
    Ray actors (SB3's `VecMonitor` keeps the episode returns for the logs); ValueError (one line)
    for a config the batch does not run."""
    train = config.train
    assert train.worlds is not None, "a batched training env has its worlds"
    if ray is not None:
        from stack.training.ray_shards import RayWorldShards

        return VecMonitor(RayWorldShards(config, train.worlds, train.envs, ray))
    if train.envs == 1:
        return VecMonitor(TrainingWorlds(config, train.worlds))
    return VecMonitor(WorldShards(config, train.worlds, train.envs))
