"""Tabular Q-learning (epsilon-greedy), on any env whose observation is a small integer vector.

The table has one axis per state component (sizes from the `Box` space's high + 1) and one for
the action; Q(s, a) += alpha (r + gamma max_a' Q(s', a') (1 - terminal) - Q(s, a)). Exploration:
epsilon, multiplied by `epsilon_decay` after every non-greedy `predict` (one per training step)
down to `epsilon_min`; the defaults keep it fixed, as in the paper.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from records import N_ACTIONS


class QLearning:
    """The paper's tabular agent; `predict` is greedy unless `deterministic=False`."""

    encoding = "tabular"

    def __init__(
        self,
        state_sizes: tuple[int, ...],
        actions: int = N_ACTIONS,
        alpha: float = 0.1,
        gamma: float = 0.9,
        epsilon: float = 0.2,
        seed: int = 0,
        epsilon_decay: float = 1.0,
        epsilon_min: float = 0.0,
    ) -> None:
        self.table = np.zeros((*state_sizes, actions))
        self.alpha, self.gamma, self.epsilon = alpha, gamma, epsilon
        self.epsilon_decay, self.epsilon_min = epsilon_decay, epsilon_min
        self.rng = np.random.default_rng(seed)
        self.steps = 0

    @classmethod
    def for_space(cls, space: gym.spaces.Box, **kwargs: Any) -> QLearning:
        return cls(tuple(int(h) + 1 for h in np.asarray(space.high).reshape(-1)), **kwargs)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.int64, Any]:
        if not deterministic:
            explore = self.rng.random() < self.epsilon
            self.epsilon = max(self.epsilon_min, self.epsilon * self.epsilon_decay)
            if explore:
                return np.int64(self.rng.integers(self.table.shape[-1])), state
        values = self.table[tuple(np.asarray(observation, dtype=np.int64))]
        return np.int64(np.argmax(values)), state

    def update(
        self,
        observation: np.ndarray,
        action: int | np.integer,
        reward: float,
        next_observation: np.ndarray,
        terminal: bool,
    ) -> None:
        index = (*np.asarray(observation, dtype=np.int64), int(action))
        future = (
            0.0
            if terminal
            else self.gamma * self.table[tuple(np.asarray(next_observation, dtype=np.int64))].max()
        )
        self.table[index] += self.alpha * (reward + future - self.table[index])

    def learn(
        self,
        env: gym.Env,
        steps: int,
        seed: int = 0,
        on_step: Callable[[QLearning, dict], bool] | None = None,
        observation: np.ndarray | None = None,
    ) -> QLearning:
        """Train for `steps` env steps from a reset with `seed`, or from `observation` of an episode
        under way (a resumed run); `on_step(self, info)` may return False to stop early."""
        if observation is None:
            observation, _ = env.reset(seed=seed)
        for _ in range(steps):
            action, _ = self.predict(observation, deterministic=False)
            next_observation, reward, terminated, truncated, info = env.step(action)
            self.update(observation, action, float(reward), next_observation, terminated)
            self.steps += 1
            observation = next_observation
            if terminated or truncated:
                observation, _ = env.reset()
            if on_step is not None and on_step(self, info) is False:
                break
        return self
