"""The DeepCars reproduction's outputs: the two figures, results.md and summary.json.

Kept apart from `rows` (which trains and evaluates) so the table's layout and the figures can be
read and changed without the training code; nothing here touches an environment or a model.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib.pyplot as plt
import numpy as np

from records import Command
from stack.runtime.files import save_figure, write_json, write_text

if TYPE_CHECKING:
    from stack.deepcars.spec import Budget, Row, Rules


def plot_q_table(table: np.ndarray, path: Path, rules: str = "paper") -> None:
    """The paper's sparsity figure: which state-action values training ever touched (`rules`: the
    rule set's name, in the title)."""
    flat = table.reshape(-1, table.shape[-1])
    visited = np.any(flat != 0, axis=1)
    bins = min(len(flat), 400)
    edges = np.linspace(0, len(flat), bins + 1).astype(int)
    touched = np.array([(flat[a:b] != 0).mean(axis=0) for a, b in zip(edges[:-1], edges[1:], strict=True)])
    figure, axis = plt.subplots(figsize=(4.5, 7))
    image = axis.imshow(touched, aspect="auto", cmap="Greys", vmin=0, vmax=1, interpolation="nearest")
    figure.colorbar(image, ax=axis, label="share of the bin's state-actions touched")
    axis.set_xticks([int(c) for c in Command], [c.name.lower() for c in Command])
    axis.set_xlabel("action")
    axis.set_ylabel(f"state index, {bins} bins of {len(flat) / bins:.0f}")
    axis.set_title(f"Q-table ({rules} rules): {visited.mean():.1%} of {len(flat)} states visited")
    figure.tight_layout()
    save_figure(figure, path, dpi=100)
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
    save_figure(figure, path, dpi=100)
    plt.close(figure)


def markdown(rows: list[Row], quick: bool, rules: list[Rules]) -> str:
    """results.md: the table, one line per row, with the paper's numbers alongside; under it, what
    each rule set in the `rules` column means."""

    def pct(value: float | None) -> str:
        return "-" if value is None else f"{value:.2f} %"

    lines = [
        f"# DeepCars reproduction{' (quick budgets)' if quick else ''}",
        "",
        "| rules | agent | network | training steps | train accuracy | eval accuracy (greedy) "
        "| eval collisions | eval passed | wall time s | paper train | paper eval |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.rules} | {r.agent} | {r.network} | {r.training_steps} | {pct(r.train_accuracy)} | "
            f"{pct(r.eval_accuracy)} | {r.eval_collisions} | {r.eval_passed} | {r.wall_time_s:.1f} | "
            f"{pct(r.paper_train)} | {pct(r.paper_eval)} |"
        )
    lines += ["", "Rules:", *(f"- {r.summary}" for r in rules)]
    return "\n".join(lines) + "\n"


def write_tables(
    out: Path,
    rows: list[Row],
    budget: Budget,
    quick: bool,
    seed: int,
    rules: list[Rules],
    state: str = "complete",
) -> None:
    """summary.json (the run's settings, `state`: complete, running or interrupted, and every row
    so far, like every other run) and results.md, each written whole."""
    settings = {"quick": quick, "seed": seed, "budget": asdict(budget), "rules": [asdict(r) for r in rules]}
    write_json(out / "summary.json", {**settings, "state": state, "rows": [asdict(r) for r in rows]})
    write_text(out / "results.md", markdown(rows, quick, rules))
