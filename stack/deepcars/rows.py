"""The rows of the DeepCars table: what each one is, and how it is trained and evaluated.

One function per kind of row: `tabular` (Q-learning), `deep` (DQN or Double DQN for one network
size, with the paper's real-time validation) and `baselines` (random, always-stay and the one-row
`lookahead` rule). Each returns `Row`s; `evaluate` is the greedy evaluation they all share. The
step counts come from a `Budget`, the world's line of sight and the tabular exploration from
`Rules` (the paper's or the public code's; both in `spec`).
Writing the report lives in `report`, running the whole table in `reproduce`.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.logger import Logger

from planner.ddqn import DoubleDQN
from planner.networks import NET_ARCHS
from planner.tabular import QLearning
from planner.validation import RealTimeValidation
from records import N_ACTIONS, Command, child_seed
from stack.deepcars.report import plot_q_table
from stack.deepcars.spec import PAPER, PAPER_RULES, Budget, Row, Rules
from stack.deepcars.world import DeepCarsBatch, DeepCarsEnv, DeepCarsVecEnv

EVALUATION_STREAM = 1
"""Greedy evaluation runs on seed + this, apart from training's seed."""
VALIDATION_STREAM = 10_000
"""Real-time validation runs on seed + this."""


def evaluate(
    policy: Callable[[np.ndarray], np.ndarray],
    steps: int,
    encoding: str,
    seed: int,
    rules: Rules = PAPER_RULES,
    envs: int = 100,
) -> DeepCarsBatch:
    """Run `policy(observations) -> actions` greedily for `steps` env steps over `envs` envs."""
    batch = DeepCarsBatch(envs, line_of_sight=rules.line_of_sight, encoding=encoding, seed=seed)
    observations = batch.observe()
    for _ in range(max(1, steps // envs)):
        observations, *_ = batch.step(policy(observations))
    return batch


def lookahead(observations: np.ndarray) -> np.ndarray:
    """One-row lookahead on the tabular state: leave the lane if a car is one row ahead, for an
    adjacent lane without one."""
    ego, distances = observations[:, 0], observations[:, 1:]
    lanes = distances.shape[1]
    actions = np.full(len(observations), Command.STAY)
    threatened = distances[np.arange(len(ego)), ego] == 1
    for shift, action in ((-1, Command.LEFT), (1, Command.RIGHT)):
        target = np.clip(ego + shift, 0, lanes - 1)
        free = (target != ego) & (distances[np.arange(len(ego)), target] != 1)
        move = threatened & free & (actions == Command.STAY)
        actions[move] = action
    return actions


def baselines(budget: Budget, seed: int, rules: Rules = PAPER_RULES) -> list[Row]:
    """The rows without training: random, always-stay and the lookahead rule."""
    rng = np.random.default_rng(seed)
    policies = {
        "random": ("binary", lambda obs: rng.integers(0, N_ACTIONS, len(obs))),
        "always-stay": ("binary", lambda obs: np.full(len(obs), Command.STAY)),
        "lookahead-rule": ("tabular", lookahead),
    }
    rows = []
    for name, (encoding, policy) in policies.items():
        start = time.perf_counter()
        batch = evaluate(policy, budget.eval_steps, encoding, seed, rules)
        rows.append(
            Row(
                rules.name,
                name,
                "-",
                0,
                None,
                batch.accuracy,
                batch.collisions,
                batch.passed,
                time.perf_counter() - start,
                None,
                None,
            )
        )
    return rows


def tabular_learner(rules: Rules, seed: int) -> tuple[DeepCarsBatch, QLearning]:
    """The training world and the Q-learner (gamma 0.9, alpha 0.1; epsilon by `rules`)."""
    train = DeepCarsBatch(1, line_of_sight=rules.line_of_sight, encoding="tabular", seed=seed)
    agent = QLearning.for_space(
        train.observation_space(),
        alpha=0.1,
        gamma=0.9,
        epsilon=rules.epsilon_start,
        epsilon_decay=rules.epsilon_decay,
        epsilon_min=rules.epsilon_min,
        seed=seed,
    )
    return train, agent


def tabular(
    budget: Budget, seed: int, out: Path, steps: int | None = None, rules: Rules = PAPER_RULES
) -> Row:
    """Q-learning for `steps` (the paper's 50k by default) steps; the Q-table figure for the paper
    budget (`tabular_q_table.png`, `tabular_q_table-public.png` under the public rules)."""
    steps = steps or budget.tabular_steps
    start = time.perf_counter()
    train, agent = tabular_learner(rules, seed)
    observation = train.observe()[0]
    for _ in range(steps):
        action, _ = agent.predict(observation, deterministic=False)
        next_observations, rewards, crashed, _, counts = train.step(np.array([action]))
        agent.update(observation, action, float(rewards[0]), counts["final_observation"][0], bool(crashed[0]))
        observation = next_observations[0]
    greedy = lambda obs: np.argmax(agent.table[tuple(obs.T)], axis=1)  # noqa: E731
    batch = evaluate(greedy, budget.eval_steps, "tabular", child_seed(seed, EVALUATION_STREAM), rules)
    if steps == budget.tabular_steps:
        suffix = "" if rules == PAPER_RULES else f"-{rules.name}"
        plot_q_table(agent.table, out / f"tabular_q_table{suffix}.png", rules.name)
    return Row(
        rules.name,
        "tabular",
        "-",
        steps,
        train.accuracy,
        batch.accuracy,
        batch.collisions,
        batch.passed,
        time.perf_counter() - start,
        PAPER["tabular"]["train"],
        PAPER["tabular"]["eval"],
    )


class StopWhenPerfect(BaseCallback):
    """Stop once a long validation saw no collision (the paper's best model cannot improve)."""

    def __init__(self, validation: RealTimeValidation) -> None:
        super().__init__()
        self.validation = validation

    def _on_step(self) -> bool:
        last = self.validation.history[-1] if self.validation.history else None
        return not (
            last and last.period == "long" and last.step == self.num_timesteps and last.collision_rate == 0
        )


def deep(
    algorithm: str, network: str, budget: Budget, seed: int, rules: Rules = PAPER_RULES
) -> tuple[Row, list[float]]:
    """DQN or Double DQN (`algorithm`) with the `network` of `NET_ARCHS`, the best validated model
    evaluated; also the training episodes' returns (for the training curves). Its logger writes
    nowhere: left to SB3, each model made an empty `SB3-<time>` folder in the system's temp
    directory."""
    start = time.perf_counter()
    sight = rules.line_of_sight
    vec = DeepCarsVecEnv(DeepCarsBatch(8, line_of_sight=sight, encoding="binary", seed=seed))
    model = (DoubleDQN if algorithm == "ddqn" else DQN)(
        "MlpPolicy",
        vec,
        learning_rate=1e-3,
        buffer_size=50_000,
        learning_starts=1_000,
        batch_size=64,
        gamma=0.9,
        train_freq=1,
        gradient_steps=2,
        target_update_interval=250,
        exploration_fraction=0.1,
        exploration_final_eps=0.02,
        policy_kwargs={"net_arch": NET_ARCHS[network]},
        seed=seed,
        device="cpu",
    )
    model.set_logger(Logger(folder=None, output_formats=[]))
    best: dict = {}
    validation = RealTimeValidation(
        DeepCarsEnv(line_of_sight=sight, encoding="binary"),
        budget.short_every,
        budget.short_episodes,
        budget.long_every,
        budget.long_episodes,
        child_seed(seed, VALIDATION_STREAM),
        on_improvement=lambda m, v: best.update(weights=copy.deepcopy(m.policy.q_net.state_dict())),
    )
    model.learn(budget.dqn_max_steps, callback=CallbackList([validation, StopWhenPerfect(validation)]))
    if "weights" in best:
        model.policy.q_net.load_state_dict(best["weights"])

    def greedy(observations: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return model.policy.q_net(th.as_tensor(observations)).argmax(dim=1).numpy()

    batch = evaluate(greedy, budget.eval_steps, "binary", child_seed(seed, EVALUATION_STREAM), rules)
    row = Row(
        rules.name,
        algorithm,
        network,
        int(model.num_timesteps),
        vec.batch.accuracy,
        batch.accuracy,
        batch.collisions,
        batch.passed,
        time.perf_counter() - start,
        None,
        PAPER[algorithm]["eval"],
    )
    return row, vec.finished_returns
