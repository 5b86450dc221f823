"""`drivestack reproduce deepcars`: the paper's DeepCars table, reproduced.

Rows: tabular Q-learning (gamma 0.9, alpha 0.1, epsilon 0.2; 50k training steps), DQN and Double
DQN (SB3 + `planner.ddqn.DoubleDQN`) for every network size of the paper, trained up to 500k steps
with the paper's real-time validation (the best model is kept; training stops early once a long
validation is collision-free), and the baselines random, always-stay and one-row lookahead. Every
row is evaluated over 100k greedy steps on fresh seeded envs. Accuracy = passed / (passed +
collided) x 100.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from planner.ddqn import DoubleDQN
from planner.networks import NET_ARCHS
from planner.tabular import QLearning
from planner.validation import RealTimeValidation
from stack.deepcars.world import STAY, DeepCarsBatch, DeepCarsEnv, DeepCarsVecEnv

PAPER = {
    "tabular": {"train": 98.28, "eval": 99.14},
    "dqn": {"eval": 100.0},
    "ddqn": {"eval": 100.0},
}
"""The paper's accuracies [%] (Moghadam & Elkaim 2019, section 4)."""


@dataclass(frozen=True)
class Budget:
    tabular_steps: int = 50_000
    tabular_long_steps: int = 1_000_000
    dqn_max_steps: int = 500_000
    eval_steps: int = 100_000
    short_every: int = 5_000
    long_every: int = 25_000
    short_episodes: int = 3
    long_episodes: int = 10


FULL = Budget()
QUICK = Budget(
    tabular_steps=5_000,
    tabular_long_steps=20_000,
    dqn_max_steps=2_000,
    eval_steps=10_000,
    short_every=1_000,
    long_every=2_000,
    short_episodes=1,
    long_episodes=2,
)


@dataclass
class Row:
    agent: str
    network: str
    training_steps: int
    train_accuracy: float | None
    eval_accuracy: float
    eval_collisions: int
    eval_passed: int
    wall_time_s: float
    paper_train: float | None
    paper_eval: float | None


def evaluate(policy, steps: int, encoding: str, seed: int, envs: int = 100) -> DeepCarsBatch:
    """Run `policy(observations) -> actions` greedily for `steps` env steps over `envs` envs."""
    batch = DeepCarsBatch(envs, encoding=encoding, seed=seed)
    observations = batch.observe()
    for _ in range(max(1, steps // envs)):
        observations, *_ = batch.step(policy(observations))
    return batch


def lookahead(observations: np.ndarray) -> np.ndarray:
    """One-row lookahead on the tabular state: leave the lane if a car is one row ahead, for an
    adjacent lane without one."""
    ego, distances = observations[:, 0], observations[:, 1:]
    lanes = distances.shape[1]
    actions = np.full(len(observations), STAY)
    threatened = distances[np.arange(len(ego)), ego] == 1
    for shift, action in ((-1, 0), (1, 2)):
        target = np.clip(ego + shift, 0, lanes - 1)
        free = (target != ego) & (distances[np.arange(len(ego)), target] != 1)
        move = threatened & free & (actions == STAY)
        actions[move] = action
    return actions


def baselines(budget: Budget, seed: int) -> list[Row]:
    rng = np.random.default_rng(seed)
    policies = {
        "random": ("binary", lambda obs: rng.integers(0, 3, len(obs))),
        "always-stay": ("binary", lambda obs: np.full(len(obs), STAY)),
        "lookahead-rule": ("tabular", lookahead),
    }
    rows = []
    for name, (encoding, policy) in policies.items():
        start = time.perf_counter()
        batch = evaluate(policy, budget.eval_steps, encoding, seed)
        rows.append(
            Row(
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


def tabular(budget: Budget, seed: int, out: Path, steps: int | None = None) -> Row:
    """Q-learning for `steps` (the paper's 50k by default) steps; the Q-table figure for the paper budget."""
    steps = steps or budget.tabular_steps
    start = time.perf_counter()
    train = DeepCarsBatch(1, encoding="tabular", seed=seed)
    agent = QLearning.for_space(train.observation_space(), alpha=0.1, gamma=0.9, epsilon=0.2, seed=seed)
    observation = train.observe()[0]
    for _ in range(steps):
        action, _ = agent.predict(observation, deterministic=False)
        next_observations, rewards, crashed, _, counts = train.step(np.array([action]))
        agent.update(observation, action, float(rewards[0]), counts["final_observation"][0], bool(crashed[0]))
        observation = next_observations[0]
    greedy = lambda obs: np.argmax(agent.table[tuple(obs.T)], axis=1)  # noqa: E731
    batch = evaluate(greedy, budget.eval_steps, "tabular", seed + 1)
    if steps == budget.tabular_steps:
        plot_q_table(agent.table, out / "tabular_q_table.png")
    return Row(
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


def deep(algorithm: str, network: str, budget: Budget, seed: int) -> tuple[Row, list[float]]:
    start = time.perf_counter()
    vec = DeepCarsVecEnv(DeepCarsBatch(8, encoding="binary", seed=seed))
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
    best: dict = {}
    validation = RealTimeValidation(
        DeepCarsEnv(encoding="binary"),
        budget.short_every,
        budget.short_episodes,
        budget.long_every,
        budget.long_episodes,
        seed + 10_000,
        on_improvement=lambda m, v: best.update(weights=copy.deepcopy(m.policy.q_net.state_dict())),
    )
    model.learn(budget.dqn_max_steps, callback=CallbackList([validation, StopWhenPerfect(validation)]))
    if "weights" in best:
        model.policy.q_net.load_state_dict(best["weights"])

    def greedy(observations: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return model.policy.q_net(th.as_tensor(observations)).argmax(dim=1).numpy()

    batch = evaluate(greedy, budget.eval_steps, "binary", seed + 1)
    row = Row(
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


def plot_q_table(table: np.ndarray, path: Path) -> None:
    """The paper's sparsity figure: which state-action values training ever touched."""
    flat = table.reshape(-1, table.shape[-1])
    visited = np.any(flat != 0, axis=1)
    crop = flat[: min(len(flat), 400)]
    figure, axis = plt.subplots(figsize=(4, 7))
    axis.imshow(crop != 0, aspect="auto", cmap="Greys", interpolation="nearest")
    axis.set_xticks([0, 1, 2], ["left", "stay", "right"])
    axis.set_ylabel("state index (first 400)")
    axis.set_title(f"Q-table: {visited.mean():.1%} of {len(flat)} states visited")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def plot_curves(curves: dict[tuple[str, str], list[float]], path: Path) -> None:
    """Mean episode reward over the last 100 episodes, per network, DQN vs DDQN."""
    figure, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    for axis, algorithm in zip(axes, ("dqn", "ddqn"), strict=True):
        for (name, network), returns in curves.items():
            if name != algorithm or not returns:
                continue
            window = (
                np.convolve(returns, np.ones(100) / 100, mode="valid") if len(returns) >= 100 else returns
            )
            axis.plot(window, label=network)
        axis.set_title(algorithm.upper())
        axis.set_xlabel("episode")
        axis.legend(fontsize="small")
    axes[0].set_ylabel("mean reward (last 100 episodes)")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def markdown(rows: list[Row], quick: bool) -> str:
    def pct(value):
        return "-" if value is None else f"{value:.2f} %"

    lines = [
        f"# DeepCars reproduction{' (quick budgets)' if quick else ''}",
        "",
        "| agent | network | training steps | train accuracy | eval accuracy (greedy) | eval collisions "
        "| eval passed | wall time s | paper train | paper eval |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.agent} | {r.network} | {r.training_steps} | {pct(r.train_accuracy)} | "
            f"{pct(r.eval_accuracy)} | {r.eval_collisions} | {r.eval_passed} | {r.wall_time_s:.1f} | "
            f"{pct(r.paper_train)} | {pct(r.paper_eval)} |"
        )
    return "\n".join(lines) + "\n"


def reproduce(out: Path, quick: bool = False, seed: int = 0, progress=None) -> list[Row]:
    out.mkdir(parents=True, exist_ok=True)
    budget = QUICK if quick else FULL
    rows = [tabular(budget, seed, out), tabular(budget, seed, out, budget.tabular_long_steps)]
    if progress:
        progress("tabular")
    curves = {}
    for algorithm in ("dqn", "ddqn"):
        for network in NET_ARCHS:
            row, returns = deep(algorithm, network, budget, seed)
            rows.append(row)
            curves[(algorithm, network)] = returns
            if progress:
                progress(f"{algorithm} {network}")
    rows += baselines(budget, seed)
    plot_curves(curves, out / "training_curves.png")
    (out / "summary.json").write_text(
        json.dumps(
            {"quick": quick, "seed": seed, "budget": asdict(budget), "rows": [asdict(r) for r in rows]},
            indent=2,
        )
        + "\n"
    )
    (out / "results.md").write_text(markdown(rows, quick))
    return rows
