"""`drivestack reproduce deepcars`: the paper's DeepCars table, reproduced.

Rows: tabular Q-learning (gamma 0.9, alpha 0.1, epsilon 0.2; 50k training steps), DQN and Double
DQN (SB3 + `planner.ddqn.DoubleDQN`) for every network size of the paper, trained up to 500k steps
with the paper's real-time validation (the best model is kept; training stops early once a long
validation is collision-free), and the baselines random, always-stay and one-row lookahead. Every
row is evaluated over 100k greedy steps on fresh seeded envs. Accuracy = passed / (passed +
collided) x 100. `variants` picks the rule sets (`spec.RULES`: the paper's text, the authors' public
code); with more than one, the whole table runs under each, one block of rows per rule set.

This module only runs the rows in the table's order and hands them to the report; how a row is
trained and evaluated is in `rows`, the figures and tables in `report`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from stack.deepcars.report import plot_curves, write_tables
from stack.deepcars.rows import baselines, deep, lookahead, tabular
from stack.deepcars.spec import FULL, PAPER_NETWORKS, QUICK, RULES, Budget, Row
from stack.runtime.interrupts import deferred

__all__ = ["FULL", "QUICK", "Budget", "Row", "lookahead", "reproduce"]


def reproduce(
    out: Path,
    quick: bool = False,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    *,
    budget: Budget | None = None,
    networks: Sequence[str] = PAPER_NETWORKS,
    variants: Sequence[str] = ("paper",),
) -> list[Row]:
    """Train and evaluate every row into `out` (summary.json, results.md, the figures), under each
    rule set of `variants` in turn. Each finished row is written at once (summary `state`
    running); Ctrl-C keeps the rows finished (`state` interrupted), none raises KeyboardInterrupt.

    `budget` defaults to `QUICK` or `FULL` by `quick`; `networks` (`PAPER_NETWORKS` by default)
    narrows the DQN/DDQN rows, for smoke tests."""
    out.mkdir(parents=True, exist_ok=True)
    budget = budget or (QUICK if quick else FULL)
    rule_sets = [RULES[name] for name in variants]
    rows: list[Row] = []
    curves = {}

    def finished(*new: Row) -> None:
        rows.extend(new)
        with deferred():
            write_tables(out, rows, budget, quick, seed, rule_sets, "running")

    interrupted = False
    try:
        for rules in rule_sets:
            finished(
                tabular(budget, seed, out, rules=rules),
                tabular(budget, seed, out, budget.tabular_long_steps, rules),
            )
            if progress:
                progress(f"tabular ({rules.name})")
            for algorithm in ("dqn", "ddqn"):
                for network in networks:
                    row, returns = deep(algorithm, network, budget, seed, rules)
                    label = network if len(variants) == 1 else f"{network} ({rules.name})"
                    curves[(algorithm, label)] = returns
                    finished(row)
                    if progress:
                        progress(f"{algorithm} {network} ({rules.name})")
            finished(*baselines(budget, seed, rules))
    except KeyboardInterrupt:
        interrupted = True
    if not rows:
        raise KeyboardInterrupt
    with deferred(interrupt_after=False):
        if curves:
            plot_curves(curves, out / "training_curves.png")
        write_tables(out, rows, budget, quick, seed, rule_sets, "interrupted" if interrupted else "complete")
    return rows
