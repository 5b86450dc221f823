"""The paper's real-time validation (Algorithm 1) as an SB3 callback.

Two validation periods: a short one, run often on few episodes, and a long one, run rarely on many,
with greedy actions on a separate env; episode k of every validation uses seed + k, so validations of
one period see the same episodes. Scores (lower collision rate first, then higher mean return) are
compared within a period only: a mean over 4 episodes says nothing against a mean over 16 other
ones. A short validation that beats the best short score promotes the model to a long validation at
once; the model is kept whenever a long validation beats the best long score.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from planner.scores import Validation, WorldScore
from records import child_seed


@dataclass(frozen=True)
class Score:
    """What `validate` measured: collision rate, mean return, mean speed [m/s], and per world."""

    collision_rate: float
    mean_return: float
    mean_speed: float
    worlds: dict[str, WorldScore]


@dataclass(frozen=True)
class ValidationEpisode:
    """One validation episode: the world it drew (`""` without a mix), whether the ego crashed,
    its return, and the ego's speed [m/s] after each decision."""

    world: str
    crashed: bool
    total: float
    speeds: list[float]


def scored(episodes: Sequence[ValidationEpisode]) -> Score:
    """The score of validation episodes, in episode order (means over every decision's speed, per
    world for the episodes that name one)."""
    by_world: dict[str, list[ValidationEpisode]] = {}
    for episode in episodes:
        by_world.setdefault(episode.world, []).append(episode)
    worlds = {
        name: WorldScore(
            len(played), float(np.mean([episode.crashed for episode in played])), mean_speed_of(played)
        )
        for name, played in by_world.items()
        if name
    }
    crashes = sum(episode.crashed for episode in episodes)
    mean_return = float(np.mean([episode.total for episode in episodes]))
    return Score(crashes / len(episodes), mean_return, mean_speed_of(episodes), worlds)


def mean_speed_of(episodes: Sequence[ValidationEpisode]) -> float:
    """The mean of every decision's speed [m/s] over `episodes` (NaN for none)."""
    speeds = [speed for episode in episodes for speed in episode.speeds]
    return float(np.mean(speeds)) if speeds else float("nan")


def validate(predict: Callable, env: gym.Env, episodes: int, seed: int) -> Score:
    """The score of greedy `predict` over seeded episodes of `env` (episode k from
    `child_seed(seed, k)`); an env that names the world of each episode (`world_name`, as
    `HierarchicalHighwayEnv` with a training mix) is scored per world too."""
    played = []
    for episode in range(episodes):
        observation, _ = env.reset(seed=child_seed(seed, episode))
        world = str(getattr(env.unwrapped, "world_name", ""))
        total, done = 0.0, False
        info: dict[str, Any] = {}
        speeds = []
        while not done:
            action, _ = predict(observation, deterministic=True)
            observation, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            if "speed" in info:
                speeds.append(info["speed"])
            done = terminated or truncated
        played.append(ValidationEpisode(world, bool(info.get("crashed", False)), total, speeds))
    return scored(played)


Measure = Callable[[Callable, int, int], Score]
"""(greedy predict, episodes, seed) -> their `Score`: `validate` on an env, or the same episodes
on batched worlds."""


class RealTimeValidation(BaseCallback):
    """Validate every `short_every` steps on `short_episodes` episodes and every `long_every` steps
    (and on promotion) on `long_episodes`; call `on_improvement(model, validation)` when the best long
    score improves, then `on_validation(validation)` (if given) after every validation."""

    model: Any
    """What is validated: an SB3 algorithm, or a `QLearning` its trainer sets (only `predict` is used)."""

    def __init__(
        self,
        env: gym.Env,
        short_every: int,
        short_episodes: int,
        long_every: int,
        long_episodes: int,
        seed: int,
        on_improvement: Callable[[Any, Validation], None],
        history: list[Validation] | None = None,
        best: dict[str, tuple[float, float] | None] | None = None,
        on_validation: Callable[[Validation], None] | None = None,
        measure: Measure | None = None,
    ) -> None:
        """`measure` scores the episodes (by default `validate` on `env`: one world at a time)."""
        super().__init__()
        self.measure = measure
        self.on_validation = on_validation
        self.env = env
        self.short_every, self.short_episodes = short_every, short_episodes
        self.long_every, self.long_episodes = long_every, long_episodes
        self.seed = seed
        self.on_improvement = on_improvement
        self.history = history if history is not None else []
        self.best = best or {"short": None, "long": None}
        self.last_step: int | None = None

    def _on_training_start(self) -> None:
        self.last_step = self.model.num_timesteps

    def _on_step(self) -> bool:
        self.at_step(self.num_timesteps)
        return True

    def at_step(self, step: int) -> None:
        """Run the validations due when the environment steps reach `step` (with N environments
        they advance N at a time: a period is due when a multiple of it was passed)."""
        last = step - 1 if self.last_step is None else self.last_step
        self.last_step = self.num_timesteps = step

        def due(every: int) -> bool:
            return step // every > last // every

        if due(self.long_every):
            self.run_validation("long", self.long_episodes)
        elif due(self.short_every) and self.run_validation("short", self.short_episodes).improved:
            self.run_validation("long", self.long_episodes)

    def validate_start(self, model: Any) -> Validation:
        """Validate the model training starts from (pre-trained, say) on the long period, at
        step 0: it is the first candidate to keep."""
        self.model, self.num_timesteps = model, 0
        return self.run_validation("long", self.long_episodes)

    def run_validation(self, period: str, episodes: int) -> Validation:
        """Validate now; `improved` in the result means it beat the best score of its period."""
        if self.measure is not None:
            measured = self.measure(self.model.predict, episodes, self.seed)
        else:
            measured = validate(self.model.predict, self.env, episodes, self.seed)
        score = (-measured.collision_rate, measured.mean_return)
        best = self.best[period]
        improved = best is None or score > best
        result = Validation(
            self.num_timesteps,
            period,
            episodes,
            measured.collision_rate,
            measured.mean_return,
            measured.mean_speed,
            improved,
            measured.worlds,
        )
        self.history.append(result)
        logger = getattr(self.model, "logger", None)
        if logger is not None:
            logger.record("validation/collision_rate", measured.collision_rate)
            logger.record("validation/mean_return", measured.mean_return)
            logger.record("validation/mean_speed", measured.mean_speed)
            for name, world in measured.worlds.items():
                logger.record(f"validation/{name}/mean_speed", world.mean_speed)
                logger.record(f"validation/{name}/collision_rate", world.collision_rate)
        if improved:
            self.best[period] = score
            if period == "long":
                self.on_improvement(self.model, result)
        if self.on_validation is not None:
            self.on_validation(result)
        return result

    def state(self) -> dict:
        """JSON-ready state for checkpoints."""
        best = {period: list(score) if score else None for period, score in self.best.items()}
        return {"best": best, "history": [asdict(v) for v in self.history]}

    @staticmethod
    def restore(state: dict) -> tuple[list[Validation], dict[str, tuple[float, float] | None]]:
        history = [Validation.from_json(entry) for entry in state.get("history", [])]
        best = state.get("best")
        best = best if isinstance(best, dict) else {}  # checkpoints before per-period bests: restart them

        return history, {
            period: tuple(best[period]) if best.get(period) else None for period in ("short", "long")
        }
