"""The paper's real-time validation (Algorithm 1) as an SB3 callback.

Two validation periods: a short one, run often on few episodes, and a long one, run rarely on many.
Both replay the same seeded validation episodes (episode k uses seed + k) with greedy actions on a
separate env, so every validation is comparable. A model is kept whenever it improves on the best
so far: lower collision rate first, then higher mean return.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback


@dataclass(frozen=True)
class Validation:
    """One validation run: at `step`, over `episodes` episodes."""

    step: int
    period: str
    episodes: int
    collision_rate: float
    mean_return: float
    mean_speed: float
    improved: bool

    @property
    def score(self) -> tuple[float, float]:
        return (-self.collision_rate, self.mean_return)


def validate(predict: Callable, env: gym.Env, episodes: int, seed: int) -> tuple[float, float, float]:
    """(collision rate, mean return, mean speed [m/s]) of greedy `predict` over seeded episodes."""
    crashes, returns, speeds = 0, [], []
    for episode in range(episodes):
        observation, _ = env.reset(seed=seed + episode)
        total, done, info = 0.0, False, {}
        while not done:
            action, _ = predict(observation, deterministic=True)
            observation, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            if "speed" in info:
                speeds.append(info["speed"])
            done = terminated or truncated
        crashes += bool(info.get("crashed", False))
        returns.append(total)
    return crashes / episodes, float(np.mean(returns)), float(np.mean(speeds)) if speeds else float("nan")


class RealTimeValidation(BaseCallback):
    """Validate every `short_every` steps on `short_episodes` episodes and every `long_every` steps
    on `long_episodes`; call `on_improvement(model, validation)` when the best score improves."""

    def __init__(
        self,
        env: gym.Env,
        short_every: int,
        short_episodes: int,
        long_every: int,
        long_episodes: int,
        seed: int,
        on_improvement: Callable[[object, Validation], None],
        history: list[Validation] | None = None,
        best: tuple[float, float] | None = None,
    ) -> None:
        super().__init__()
        self.env = env
        self.short_every, self.short_episodes = short_every, short_episodes
        self.long_every, self.long_episodes = long_every, long_episodes
        self.seed = seed
        self.on_improvement = on_improvement
        self.history = history if history is not None else []
        self.best = best

    def _on_step(self) -> bool:
        step = self.num_timesteps
        if step % self.long_every == 0:
            self.run_validation("long", self.long_episodes)
        elif step % self.short_every == 0:
            self.run_validation("short", self.short_episodes)
        return True

    def run_validation(self, period: str, episodes: int) -> Validation:
        collision_rate, mean_return, mean_speed = validate(self.model.predict, self.env, episodes, self.seed)
        score = (-collision_rate, mean_return)
        improved = self.best is None or score > self.best
        result = Validation(
            self.num_timesteps, period, episodes, collision_rate, mean_return, mean_speed, improved
        )
        self.history.append(result)
        logger = getattr(self.model, "logger", None)
        if logger is not None:
            logger.record("validation/collision_rate", collision_rate)
            logger.record("validation/mean_return", mean_return)
            logger.record("validation/mean_speed", mean_speed)
        if improved:
            self.best = score
            self.on_improvement(self.model, result)
        return result

    def state(self) -> dict:
        """JSON-ready state for checkpoints."""
        return {"best": list(self.best) if self.best else None, "history": [asdict(v) for v in self.history]}

    @staticmethod
    def restore(state: dict) -> tuple[list[Validation], tuple[float, float] | None]:
        history = [Validation(**entry) for entry in state.get("history", [])]
        best = tuple(state["best"]) if state.get("best") else None
        return history, best
