"""The batched training env's shards as Ray actors (`drivestack train --ray [ADDRESS]`): the
`train.worlds` worlds split into `train.envs` shards as `WorldShards` splits them over local
processes, each shard a `TrainingWorlds` in a Ray actor of one CPU, on whichever node of the
cluster has one free; the learner stays in this process. The actors answer the very requests the
shard processes answer (`world_shards.answer`), so a run is bit for bit the one of `train.envs`
local processes. Shipped to each actor once: the resolved config and this process's import path
(plug-ins); each step: the shard's actions down, its observations, rewards, ends and infos up."""

from __future__ import annotations

import signal
import socket
from collections.abc import Sequence
from typing import Any

from stack.runtime.ray_tasks import connect, extend_path, import_path, task_result
from stack.settings.run import RunConfig
from stack.training.batch_env import TrainingWorlds
from stack.training.decision_batch import batch_config
from stack.training.world_shards import ShardDied, ShardedWorlds, answer


class WorldsActor:
    """One shard of worlds in a Ray actor: `worlds` worlds of `config`, importing from the
    driver's `path` as a `--ray` task does; deaf to Ctrl-C, as the shard processes (the learner
    stops the run with a checkpoint, which asks the shards for their episodes)."""

    def __init__(self, config: RunConfig, worlds: int, path: Sequence[str]) -> None:
        extend_path(path)
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:
            pass
        self.shard = TrainingWorlds(config, worlds)

    def host(self) -> str:
        """The name of the machine this actor runs on."""
        return socket.gethostname()

    def ask(self, request: str, data: Any) -> Any:
        """The shard's answer to the learner's `request` (with its `data`)."""
        return answer(self.shard, request, data)

    def close(self) -> None:
        self.shard.close()


class RayWorldShards(ShardedWorlds):
    """`worlds` worlds of `config` in `shards` Ray actors of `worlds / shards` worlds each, on the
    Ray instance or cluster at `address` (`local`, `auto`, HOST:PORT); a dead actor is `ShardDied`
    naming the shard, its worlds and its machine."""

    def __init__(self, config: RunConfig, worlds: int, shards: int, address: str) -> None:
        super().__init__(worlds, shards)
        batch_config(config)
        self.ray = connect(address)
        remote = self.ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(WorldsActor)
        path = self.ray.put(import_path())
        size = worlds // shards
        self.actors = [remote.remote(config, size, path) for _ in range(shards)]
        self.pending: list[Any] = [None] * shards
        self.hosts = ["a node of the cluster"] * shards
        try:
            for shard, actor in enumerate(self.actors):
                self.pending[shard] = actor.host.remote()
            self.hosts = [self._receive(shard) for shard in range(shards)]
            self._send(0, "observation_space", None)
            self._start(self._receive(0))
        except BaseException:
            self.abandon()
            raise

    def _send(self, shard: int, request: str, data: Any) -> None:
        self.pending[shard] = self.actors[shard].ask.remote(request, data)

    def _receive(self, shard: int) -> Any:
        ref, self.pending[shard] = self.pending[shard], None
        try:
            return task_result(self.ray, ref)
        except self.ray.exceptions.RayActorError as error:
            part = self.parts[shard]
            raise ShardDied(
                f"world shard {shard + 1} of {len(self.parts)} (worlds {part.start}-{part.stop - 1}, "
                f"the Ray actor on {self.hosts[shard]}) died ({type(error).__name__})"
            ) from None

    def close(self) -> None:
        """End the actors: a step under way is read first, then each closes its worlds and ends."""
        if self.closed:
            return
        if self.waiting:
            for shard in range(len(self.parts)):
                self._receive(shard)
        self.pending = [actor.close.remote() for actor in self.actors]
        for shard in range(len(self.parts)):
            self._receive(shard)
        self.abandon()

    def abandon(self) -> None:
        for actor in self.actors:
            self.ray.kill(actor)
        self.closed = True
