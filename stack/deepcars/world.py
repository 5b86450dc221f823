"""DeepCars, the paper's grid world, as a numpy batch of environments and as gymnasium envs.

The road has `lanes` lanes and `line_of_sight` rows; row 0 is the ego's row, row line_of_sight-1
the top. One step:
1. the ego moves one lane (`records.Command`: LEFT = towards lane 0); a move off the road is a no-op;
2. every car moves one row down; cars leaving row 0 are passed;
3. a car now in the ego's cell is a collision: reward -1, the episode ends; otherwise +1;
4. with probability `spawn_probability` one car appears in a random lane of the top row.

Observations: `grid` (rows x lanes occupancy, flattened, row 0 first) + the ego lane as a binary code
(the paper) or one-hot (the public code), or `tabular`: [ego_lane, rows to the closest car in each
lane, capped at line_of_sight - 1]. `DeepCarsBatch` steps many envs at once; `DeepCarsVecEnv` hands
it to stable-baselines3; `DeepCarsEnv` (`drivestack/DeepCars-v0`) is the single gymnasium env.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from records import N_ACTIONS, Command, drawn_seed

ENCODINGS = ("binary", "one-hot", "tabular")


def code_bits(lanes: int) -> int:
    return max(1, math.ceil(math.log2(lanes)))


class DeepCarsBatch:
    """`n` DeepCars envs stepped together; finished envs reset on their own (SB3 convention).

    State: `cars` (n, rows, lanes) bool, `ego` (n,) lane; counters `passed`, `collisions`,
    `steps` (totals over all envs since construction)."""

    def __init__(
        self,
        n: int = 1,
        lanes: int = 5,
        line_of_sight: int = 9,
        spawn_probability: float = 1.0,
        encoding: str = "binary",
        max_steps: int = 1000,
        seed: int = 0,
    ) -> None:
        if lanes < 2 or line_of_sight < 2:
            raise ValueError(
                f"DeepCars needs >= 2 lanes and a line of sight >= 2, got {lanes} and {line_of_sight}"
            )
        if not 0 <= spawn_probability <= 1:
            raise ValueError(f"spawn_probability must be in [0, 1], got {spawn_probability}")
        if encoding not in ENCODINGS:
            raise ValueError(f"unknown encoding {encoding!r}; available: {', '.join(ENCODINGS)}")
        self.n, self.lanes, self.rows = n, lanes, line_of_sight
        self.spawn_probability, self.encoding, self.max_steps = spawn_probability, encoding, max_steps
        self.rng = np.random.default_rng(seed)
        self.cars = np.zeros((n, self.rows, lanes), dtype=bool)
        self.ego = np.zeros(n, dtype=np.int64)
        self.episode_steps = np.zeros(n, dtype=np.int64)
        self.passed = self.collisions = self.steps = 0
        self.reset_envs(np.ones(n, dtype=bool))

    @property
    def observation_size(self) -> int:
        if self.encoding == "tabular":
            return 1 + self.lanes
        return self.rows * self.lanes + (code_bits(self.lanes) if self.encoding == "binary" else self.lanes)

    def observation_space(self) -> spaces.Box:
        if self.encoding == "tabular":
            high = np.array([self.lanes - 1] + [self.rows - 1] * self.lanes)
            return spaces.Box(0, high, dtype=np.int64)
        return spaces.Box(0.0, 1.0, (self.observation_size,), dtype=np.float32)

    def reset_envs(self, mask: np.ndarray) -> None:
        """Empty road, ego in the middle lane, for the envs in `mask`."""
        self.cars[mask] = False
        self.ego[mask] = self.lanes // 2
        self.episode_steps[mask] = 0

    def distances(self) -> np.ndarray:
        """(n, lanes): rows to the closest car in each lane, rows - 1 when the lane is clear."""
        first = np.argmax(self.cars, axis=1)
        return np.where(self.cars.any(axis=1), first, self.rows - 1)

    def observe(self) -> np.ndarray:
        if self.encoding == "tabular":
            return np.concatenate([self.ego[:, None], self.distances()], axis=1)
        grid = self.cars.reshape(self.n, -1).astype(np.float32)
        if self.encoding == "one-hot":
            code = np.eye(self.lanes, dtype=np.float32)[self.ego]
        else:
            bits = code_bits(self.lanes)
            code = ((self.ego[:, None] >> np.arange(bits - 1, -1, -1)) & 1).astype(np.float32)
        return np.concatenate([grid, code], axis=1)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """(observations, rewards, terminated, truncated, counts); envs that ended are reset and
        their observation is the first of the next episode (`counts["final_observation"]` holds
        the last one)."""
        actions = np.asarray(actions).reshape(self.n)
        lane_shifts = actions - Command.STAY  # Command.lane_shift, for a whole array of actions
        self.ego = np.clip(self.ego + lane_shifts, 0, self.lanes - 1)
        passed = self.cars[:, 0, :].sum(axis=1)
        self.cars[:, :-1] = self.cars[:, 1:]
        self.cars[:, -1] = False
        crashed = self.cars[np.arange(self.n), 0, self.ego]
        spawn = self.rng.random(self.n) < self.spawn_probability
        lanes = self.rng.integers(0, self.lanes, self.n)
        self.cars[np.flatnonzero(spawn), -1, lanes[spawn]] = True
        self.episode_steps += 1
        truncated = ~crashed & (self.episode_steps >= self.max_steps)
        rewards = np.where(crashed, -1.0, 1.0).astype(np.float32)
        self.passed += int(passed.sum())
        self.collisions += int(crashed.sum())
        self.steps += self.n
        final = self.observe()
        done = crashed | truncated
        if done.any():
            self.reset_envs(done)
        return self.observe(), rewards, crashed, truncated, {"final_observation": final, "passed": passed}

    @property
    def accuracy(self) -> float:
        total = self.passed + self.collisions
        return 100.0 * self.passed / total if total else float("nan")


class DeepCarsEnv(gym.Env):
    """`drivestack/DeepCars-v0`: one DeepCars env (the batch with n = 1, without auto-reset)."""

    metadata = {"render_modes": []}

    def __init__(
        self,
        lanes: int = 5,
        line_of_sight: int = 9,
        spawn_probability: float = 1.0,
        encoding: str = "binary",
        max_steps: int = 1000,
    ) -> None:
        self.settings: dict[str, Any] = dict(
            lanes=lanes,
            line_of_sight=line_of_sight,
            spawn_probability=spawn_probability,
            encoding=encoding,
            max_steps=max_steps,
        )
        self.batch = DeepCarsBatch(1, **self.settings)
        self.observation_space = self.batch.observation_space()
        self.action_space = spaces.Discrete(N_ACTIONS)

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.batch = DeepCarsBatch(1, **self.settings, seed=drawn_seed(self.np_random))
        return self.batch.observe()[0], {}

    def step(
        self, action: int | np.integer | np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        _, rewards, crashed, truncated, counts = self.batch.step(np.array([int(action)]))
        info = {"crashed": bool(crashed[0]), "passed": int(counts["passed"][0])}
        return counts["final_observation"][0], float(rewards[0]), bool(crashed[0]), bool(truncated[0]), info


class DeepCarsVecEnv(VecEnv):
    """The batch behind SB3's VecEnv interface, so DQN collects `n` transitions per step."""

    render_mode = None

    def __init__(self, batch: DeepCarsBatch) -> None:
        self.batch = batch
        super().__init__(batch.n, batch.observation_space(), spaces.Discrete(N_ACTIONS))
        self.episode_returns = np.zeros(batch.n)
        self.finished_returns: list[float] = []

    def reset(self) -> np.ndarray:
        self.batch.reset_envs(np.ones(self.batch.n, dtype=bool))
        self.episode_returns[:] = 0
        return self.batch.observe()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        observations, rewards, crashed, truncated, counts = self.batch.step(self._actions)
        self.episode_returns += rewards
        done = crashed | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.batch.n)]
        for i in np.flatnonzero(done):
            infos[i] = {
                "terminal_observation": counts["final_observation"][i],
                "TimeLimit.truncated": bool(truncated[i]),
                "episode": {"r": float(self.episode_returns[i]), "l": 0},
            }
            self.finished_returns.append(float(self.episode_returns[i]))
            self.episode_returns[i] = 0
        return observations, rewards, done, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self, attr_name)] * self.num_envs

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        return [getattr(self, method_name)(*args, **kwargs)] * self.num_envs

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * self.num_envs
