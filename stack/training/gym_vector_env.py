"""The decision MDP of N worlds in the ecosystem's two vector shapes, over one `DecisionBatch`:

- `HierarchicalHighwayVectorEnv`, a gymnasium `VectorEnv`, the vector entry point of
  `drivestack/HierarchicalHighway-v0`: `gymnasium.make_vec('drivestack/HierarchicalHighway-v0',
  num_envs=N, vectorization_mode='vector_entry_point', config=...)`. Next-step autoreset, as
  gymnasium's `SyncVectorEnv` of the per-world env, and the same episodes: world k's generator is
  seeded `seed + k` at `reset(seed=...)` and draws each episode's traffic seed as that env does.
- `DecisionVecEnv`, a stable-baselines3 `VecEnv` (same-step autoreset, `terminal_observation`
  and `TimeLimit.truncated` in the infos), so any SB3 algorithm collects N transitions a step.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from records import N_ACTIONS, TRAINING_SEED_FLOOR, drawn_seed
from stack.settings.run import RunConfig
from stack.training.decision_batch import BatchRefused, Decided, DecisionBatch, checked_commands


class SeededWorlds:
    """One generator per world, seeded as gymnasium seeds a vector env's k-th env (`seed + k`, or
    fresh entropy with None), drawing each episode's mix member (kept in `members`) and traffic
    seed as `HierarchicalHighwayEnv` does (`batch.draw`)."""

    def __init__(self, worlds: int, batch: DecisionBatch | None = None) -> None:
        self.generators = [seeding.np_random()[0] for _ in range(worlds)]
        self.batch = batch
        self.members = [0] * worlds

    def seed(self, seed: int | Sequence[int | None] | None) -> None:
        """Seed world k with `seed + k`, or with `seed[k]` (None: left as it is); ValueError (one
        line) for anything but an integer, None or one integer or None per world."""
        worlds = len(self.generators)
        if seed is None:
            return
        seeds = [int(cast(int, seed)) + k for k in range(worlds)] if _integer(seed) else seed
        if (
            isinstance(seeds, str | bytes)
            or not isinstance(seeds, Sequence | np.ndarray)
            or len(seeds) != worlds
            or not all(value is None or _integer(value) for value in seeds)
        ):
            raise ValueError(
                f"seed: expected an integer, None or one integer (or None) per world ({worlds}), "
                f"got {repr(seed)[:60]}"
            )
        for k, value in enumerate(seeds):
            if value is not None:
                self.generators[k] = seeding.np_random(value)[0]

    def draw(self, worlds: Sequence[int]) -> list[int]:
        """The next traffic seed of each world in `worlds` (its member drawn first, in a mix)."""
        if self.batch is None:
            return [drawn_seed(self.generators[k], TRAINING_SEED_FLOOR) for k in worlds]
        seeds = []
        for k in worlds:
            self.members[k], seed = self.batch.draw(self.generators[k])
            seeds.append(seed)
        return seeds


def _integer(value: object) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def world_infos(batch: DecisionBatch, decided: Decided | None = None) -> dict[str, np.ndarray]:
    """Per world, as arrays: the per-world env's info (`crashed`, `speed`, `lane_changes`,
    `masked`, `aborted`; not `passed_cars`, which the batch does not count) and, after a step,
    the commands permitted now and whether the command given was masked or refused."""
    loop = batch.loop
    assert loop.batch is not None
    infos = {
        "crashed": loop.crashed.copy(),
        "speed": loop.batch.speed[:, 0].copy(),
        "lane_changes": loop.counts[:, 0].copy(),
        "masked": loop.counts[:, 1].copy(),
        "aborted": loop.counts[:, 2].copy(),
    }
    if decided is not None:
        infos |= {
            "permitted": decided.permitted,
            "command_masked": decided.masked,
            "command_refused": decided.refused,
        }
    return infos


class HierarchicalHighwayVectorEnv(VectorEnv):
    """`num_envs` worlds of `HierarchicalHighway-v0` (`config`: a `RunConfig` or its data) stepped
    together; rendering stays with the per-world env."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self, num_envs: int = 1, config: RunConfig | dict | None = None, render_mode: str | None = None
    ) -> None:
        if render_mode is not None:
            raise ValueError(
                "the batched decision MDP does not render: use the per-world env (vectorization_mode='sync')"
            )
        try:
            self.batch = DecisionBatch(config, num_envs)
        except BatchRefused as refused:
            raise ValueError(f"{refused}; vectorization_mode='sync' steps them one at a time") from None
        self.num_envs = num_envs = self.batch.worlds
        self.render_mode = None
        self.single_observation_space = self.batch.observation_space
        self.single_action_space = spaces.Discrete(N_ACTIONS)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.worlds = SeededWorlds(num_envs, self.batch)
        self._autoreset = np.zeros(num_envs, dtype=bool)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        self.worlds.seed(seed)
        seeds = self.worlds.draw(range(self.num_envs))
        observations = self.batch.reset(seeds, self.worlds.members)
        self._autoreset[:] = False
        return observations, _with_masks(world_infos(self.batch))

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        resetting = self._autoreset.copy()
        ended = np.flatnonzero(resetting).tolist()
        if ended:
            seeds = self.worlds.draw(ended)
            self.batch.reset_worlds(ended, seeds, [self.worlds.members[k] for k in ended])
        commands = np.where(resetting, 1, checked_commands(actions, self.num_envs))
        decided = self.batch.step(commands, only=~resetting)
        self._autoreset = decided.terminated | decided.truncated
        return (
            decided.observations,
            decided.rewards,
            decided.terminated,
            decided.truncated,
            _with_masks(world_infos(self.batch, decided)),
        )

    def close_extras(self, **kwargs: Any) -> None:
        self.batch.close()


def _with_masks(infos: dict[str, np.ndarray]) -> dict[str, Any]:
    """gymnasium's vector info layout: each key beside `_key`, which worlds hold it (all)."""
    masks = {f"_{key}": np.ones(len(value), dtype=bool) for key, value in infos.items()}
    return {**infos, **masks}


class WorldsVecEnv(VecEnv):
    """An SB3 `VecEnv` whose worlds are one object, not N gym envs: an attribute or method asked of
    any world is the whole env's, and no world is wrapped."""

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


class DecisionVecEnv(WorldsVecEnv):
    """`DecisionBatch` behind stable-baselines3's `VecEnv`: `num_envs` worlds of the decision MDP,
    each reset as soon as its episode ends (its last observation in `terminal_observation`)."""

    render_mode = None

    def __init__(self, config: RunConfig | dict | None, num_envs: int, seed: int | None = None) -> None:
        self.batch = DecisionBatch(config, num_envs)
        num_envs = self.batch.worlds
        super().__init__(num_envs, self.batch.observation_space, spaces.Discrete(N_ACTIONS))
        self.worlds = SeededWorlds(num_envs, self.batch)
        self.worlds.seed(seed)
        self._actions = np.ones(num_envs, dtype=np.int64)

    def reset(self) -> np.ndarray:
        given = [seed for seed in self._seeds]
        if any(seed is not None for seed in given):
            self.worlds.seed(given)
        self._reset_seeds()
        seeds = self.worlds.draw(range(self.num_envs))
        observations = self.batch.reset(seeds, self.worlds.members)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = checked_commands(actions, self.num_envs)

    def step_wait(self) -> VecEnvStepReturn:
        decided = self.batch.step(self._actions)
        done = decided.terminated | decided.truncated
        infos = [
            {
                "crashed": bool(decided.terminated[k]),
                "command_masked": bool(decided.masked[k]),
                "command_refused": bool(decided.refused[k]),
            }
            for k in range(self.num_envs)
        ]
        observations = decided.observations
        ended = np.flatnonzero(done).tolist()
        if ended:
            for k in ended:
                infos[k]["terminal_observation"] = observations[k].copy()
                infos[k]["TimeLimit.truncated"] = bool(decided.truncated[k])
            seeds = self.worlds.draw(ended)
            self.batch.reset_worlds(ended, seeds, [self.worlds.members[k] for k in ended])
            observations = observations.copy()
            observations[ended] = self.batch.observe()[ended]
        return observations, decided.rewards.astype(np.float32), done, infos

    def close(self) -> None:
        self.batch.close()
