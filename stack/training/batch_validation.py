"""Real-time validation on batched worlds: the episodes `planner.validation.validate` plays one
world at a time, played together as a `DecisionBatch` (each world drawn from its episode's seed as
the per-world env draws it, every world bit for bit the per-world env), each world's command
chosen by the same greedy `predict` on its own observation alone, so the score is the same, bit
for bit, at a fraction of the CPU."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from gymnasium.utils import seeding

from planner.validation import Score, ValidationEpisode, scored
from records import child_seed
from stack.runs.batch_episodes import BATCH_WORLDS, batches
from stack.settings.run import RunConfig, training_worlds
from stack.training.decision_batch import BatchRefused, DecisionBatch


class BatchedValidation:
    """`measure(predict, episodes, seed)`: `validate(predict, HierarchicalHighwayEnv(config),
    episodes, seed)`'s score from batches of at most `most` worlds (one `DecisionBatch` kept for
    each batch size a validation asks for)."""

    def __init__(self, config: RunConfig, most: int = BATCH_WORLDS) -> None:
        self.config, self.most = config, most
        self.world_names = list(training_worlds(config))
        self.built: dict[int, DecisionBatch] = {}

    @classmethod
    def of(cls, config: RunConfig) -> BatchedValidation | None:
        """The batched validation of `config`, or None when a batch does not run its worlds."""
        try:
            DecisionBatch(config, 1).close()
        except BatchRefused:
            return None
        return cls(config)

    def measure(self, predict: Callable, episodes: int, seed: int) -> Score:
        seeds = [child_seed(seed, episode) for episode in range(episodes)]
        played: list[ValidationEpisode] = []
        for part in batches(seeds, 1, self.most):
            played += self.played(predict, part)
        return scored(played)

    def played(self, predict: Callable, seeds: list[int]) -> list[ValidationEpisode]:
        """The episodes of `seeds` (each as `env.reset(seed=...)` draws it) played to their end
        together, each world's commands from `predict` on its observation alone."""
        if (batch := self.built.get(len(seeds))) is None:
            batch = self.built[len(seeds)] = DecisionBatch(self.config, len(seeds))
        worlds = len(seeds)
        drawn = [batch.draw(seeding.np_random(seed)[0]) for seed in seeds]
        members = [member for member, _ in drawn]
        observation = batch.reset([traffic for _, traffic in drawn], members)
        totals = [0.0] * worlds
        speeds: list[list[float]] = [[] for _ in range(worlds)]
        live, crashed = np.ones(worlds, dtype=bool), np.zeros(worlds, dtype=bool)
        while live.any():
            commands = np.zeros(worlds, dtype=np.int64)
            for k in np.flatnonzero(live).tolist():
                commands[k] = int(predict(observation[k], deterministic=True)[0])
            decided = batch.step(commands, live)
            observation = decided.observations
            ego_speed = batch.loop.batch.speed[:, 0]  # type: ignore[union-attr]
            for k in np.flatnonzero(live).tolist():
                totals[k] += float(decided.rewards[k])
                speeds[k].append(float(ego_speed[k]))
            crashed |= decided.terminated
            live &= ~(decided.terminated | decided.truncated)
        return [
            ValidationEpisode(self.world_names[members[k]], bool(crashed[k]), totals[k], speeds[k])
            for k in range(worlds)
        ]

    def close(self) -> None:
        for batch in self.built.values():
            batch.close()
        self.built.clear()
