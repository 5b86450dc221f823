"""The batched training env (`train.worlds`): N worlds in the learner's process, one
`DecisionVecEnv` per scenario of the training mix (the worlds split by share), each keeping its
worlds' episodes under way as `EpisodeRecord`s, so a checkpoint holds them and a resumed run
replays them, as the per-world envs do."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper, VecMonitor
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from records import N_ACTIONS, Command
from stack.settings.run import RunConfig, training_worlds
from stack.training.decision_env import EpisodeRecord
from stack.training.vector_env import DecisionVecEnv, SeededWorlds


class RecordedWorlds(SeededWorlds):
    """`SeededWorlds` that keeps each world's generator state from before its last draw: where the
    world's episode under way began."""

    def __init__(self, worlds: int) -> None:
        super().__init__(worlds)
        self.starts: list[dict] = [dict(g.bit_generator.state) for g in self.generators]

    def draw(self, worlds: Sequence[int]) -> list[int]:
        for k in worlds:
            self.starts[k] = dict(self.generators[k].bit_generator.state)
        return super().draw(worlds)


class TrainingWorlds(DecisionVecEnv):
    """`DecisionVecEnv` of `worlds` worlds of `config` whose episodes under way are plain data:
    `episode_records()` for a checkpoint, `replay(records)` to rebuild them."""

    def __init__(self, config: RunConfig, worlds: int) -> None:
        super().__init__(config, worlds)
        self.worlds: RecordedWorlds = RecordedWorlds(worlds)
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
        self.batch.reset(self.worlds.draw(range(self.num_envs)))
        lengths = np.array([len(record.actions) for record in records])
        for tick in range(int(lengths.max(initial=0))):
            commands = [r.actions[tick] if tick < len(r.actions) else Command.STAY for r in records]
            self.batch.step(commands, only=lengths > tick)
        self.actions = [list(record.actions) for record in records]
        return self.batch.observe()


def world_split(shares: Sequence[float], worlds: int) -> list[int]:
    """`worlds` split by `shares` (relative), each part at least one world, the rest by largest
    remainder (ties to the first); ValueError when there are fewer worlds than shares."""
    if worlds < len(shares):
        raise ValueError(f"{worlds} worlds cannot hold a mix of {len(shares)} scenarios, one world each")
    spare = worlds - len(shares)
    exact = np.asarray(shares, dtype=float) / sum(shares) * spare
    counts = np.floor(exact).astype(int)
    for k in np.argsort(-(exact - counts), kind="stable")[: spare - int(counts.sum())]:
        counts[k] += 1
    return [1 + int(count) for count in counts]


class BatchedWorlds(VecEnv):
    """`TrainingWorlds` of the scenarios of a mix behind one stable-baselines3 `VecEnv`, their
    worlds in order (world k of the whole seeded `seed + k`, as SB3 seeds N envs)."""

    render_mode = None

    def __init__(self, parts: Sequence[TrainingWorlds]) -> None:
        shapes = {part.observation_space.shape for part in parts}
        if len(shapes) != 1:
            sizes = sorted(map(str, shapes))
            raise ValueError(f"the scenarios of a mix observe values of one size, not {sizes}")
        self.parts = list(parts)
        ends = np.cumsum([part.num_envs for part in parts]).tolist()
        self.slices = [slice(end - part.num_envs, end) for part, end in zip(parts, ends, strict=True)]
        super().__init__(ends[-1], parts[0].observation_space, spaces.Discrete(N_ACTIONS))
        self._actions = np.ones(self.num_envs, dtype=np.int64)

    def reset(self) -> np.ndarray:
        for part, worlds in zip(self.parts, self.slices, strict=True):
            part._seeds = self._seeds[worlds]
        self._reset_seeds()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return np.concatenate([part.reset() for part in self.parts])

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)

    def step_wait(self) -> VecEnvStepReturn:
        stepped = []
        for part, worlds in zip(self.parts, self.slices, strict=True):
            part.step_async(self._actions[worlds])
            stepped.append(part.step_wait())
        observations, rewards, dones, infos = zip(*stepped, strict=True)
        every: list[dict] = [info for part_infos in infos for info in part_infos]
        return np.concatenate(observations), np.concatenate(rewards), np.concatenate(dones), every

    def episode_records(self) -> tuple[EpisodeRecord, ...]:
        """Each world's episode under way, in the worlds' order."""
        return tuple(record for part in self.parts for record in part.episode_records())

    def replay(self, records: Sequence[EpisodeRecord]) -> np.ndarray:
        """`TrainingWorlds.replay` of each scenario's worlds: their observations, in order."""
        if len(records) != self.num_envs:
            raise ValueError(f"{len(records)} episodes under way for {self.num_envs} worlds")
        return np.concatenate(
            [part.replay(records[worlds]) for part, worlds in zip(self.parts, self.slices, strict=True)]
        )

    def close(self) -> None:
        for part in self.parts:
            part.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self, attr_name)] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        return [getattr(self, method_name)(*args, **kwargs)] * len(list(self._get_indices(indices)))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(list(self._get_indices(indices)))


def batched_worlds(env: VecEnv | object) -> BatchedWorlds | None:
    """The `BatchedWorlds` under `env`'s vec-env wrappers, or None for another env."""
    while isinstance(env, VecEnvWrapper):
        env = env.venv
    return env if isinstance(env, BatchedWorlds) else None


def batch_worlds_config(config: RunConfig) -> RunConfig:
    """One world of a training mix as the batch runs it: its own config, without the mix."""
    data = config.model_dump(mode="json")
    return RunConfig.model_validate({**data, "train": {**data["train"], "scenarios": {}}})


def batched_training_env(config: RunConfig) -> VecMonitor:
    """`train.worlds` worlds of `config`, split by share over the scenarios of `train.scenarios`
    (SB3's `VecMonitor` keeps the episode returns for the logs); ValueError (one line) for a
    config the batch does not run."""
    assert config.train.worlds is not None, "a batched training env has its worlds"
    worlds = training_worlds(config)
    shares = list(config.train.scenarios.values()) or [1.0]
    counts = world_split(shares, config.train.worlds)
    parts = [
        TrainingWorlds(batch_worlds_config(world), count)
        for world, count in zip(worlds.values(), counts, strict=True)
    ]
    return VecMonitor(BatchedWorlds(parts))
