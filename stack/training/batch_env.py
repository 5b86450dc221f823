"""The batched training env (`train.worlds`): N worlds of the training mix, one `DecisionVecEnv`
keeping its worlds' episodes under way as `EpisodeRecord`s, so a checkpoint holds them and a
resumed run replays them, as the per-world envs do (`world_shards` splits them over processes)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from records import Command
from stack.settings.run import RunConfig
from stack.training.decision_batch import DecisionBatch
from stack.training.decision_env import EpisodeRecord
from stack.training.gym_vector_env import DecisionVecEnv, SeededWorlds


class RecordedWorlds(SeededWorlds):
    """`SeededWorlds` that keeps each world's generator state from before its last draw: where the
    world's episode under way began."""

    def __init__(self, worlds: int, batch: DecisionBatch) -> None:
        super().__init__(worlds, batch)
        self.starts: list[dict] = [dict(g.bit_generator.state) for g in self.generators]

    def draw(self, worlds: Sequence[int]) -> list[int]:
        for k in worlds:
            self.starts[k] = dict(self.generators[k].bit_generator.state)
        return super().draw(worlds)


class ReplayableWorlds(ABC):
    """Batched worlds whose episodes under way are plain data, in world order: what a checkpoint
    keeps of them and how a resumed run rebuilds them."""

    @abstractmethod
    def episode_records(self) -> tuple[EpisodeRecord, ...]:
        """Each world's episode under way."""

    @abstractmethod
    def replay(self, records: Sequence[EpisodeRecord]) -> np.ndarray:
        """Rebuild the episodes `records` describe, one per world: the observations."""


class TrainingWorlds(DecisionVecEnv, ReplayableWorlds):
    """`DecisionVecEnv` of `worlds` worlds of `config` whose episodes under way are plain data:
    `episode_records()` for a checkpoint, `replay(records)` to rebuild them."""

    def __init__(self, config: RunConfig, worlds: int) -> None:
        super().__init__(config, worlds)
        self.worlds: RecordedWorlds = RecordedWorlds(worlds, self.batch)
        self.actions: list[list[int]] = [[] for _ in range(worlds)]

    def reset(self) -> np.ndarray:
        observations = super().reset()
        self.actions = [[] for _ in range(self.num_envs)]
        return observations

    def step_wait(self) -> VecEnvStepReturn:
        given = self._actions.tolist()
        observations, rewards, done, infos = super().step_wait()
        for k, action in enumerate(given):
            if done[k]:
                self.actions[k] = []
            else:
                self.actions[k].append(action)
        return observations, rewards, done, infos

    def episode_records(self) -> tuple[EpisodeRecord, ...]:
        """Each world's episode under way: its generator's state when it began, the actions since."""
        return tuple(
            EpisodeRecord(dict(start), list(actions))
            for start, actions in zip(self.worlds.starts, self.actions, strict=True)
        )

    def replay(self, records: Sequence[EpisodeRecord]) -> np.ndarray:
        """Rebuild the episodes `records` describe, one per world, and return the observations:
        each world's generator is put back where its episode began (it draws the same traffic seed)
        and its actions drive it alone (the other worlds wait) to the same state, since a world's
        episode depends on its seed and actions only."""
        if len(records) != self.num_envs:
            raise ValueError(f"{len(records)} episodes under way for {self.num_envs} worlds")
        for generator, record in zip(self.worlds.generators, records, strict=True):
            generator.bit_generator.state = record.generator_state
        self.batch.reset(self.worlds.draw(range(self.num_envs)), self.worlds.members)
        lengths = np.array([len(record.actions) for record in records])
        for tick in range(int(lengths.max(initial=0))):
            commands = [r.actions[tick] if tick < len(r.actions) else Command.STAY for r in records]
            self.batch.step(commands, only=lengths > tick)
        self.actions = [list(record.actions) for record in records]
        return self.batch.observe()


def batched_worlds(env: VecEnv | object) -> ReplayableWorlds | None:
    """The batched worlds (in this process or sharded over several) under `env`'s vec-env
    wrappers, or None for another env."""
    while isinstance(env, VecEnvWrapper):
        env = env.venv
    return env if isinstance(env, ReplayableWorlds) else None
