"""What a training run reports: `summary.json` (a `TrainSummary`), `validation.json` and the
training curve."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import matplotlib.pyplot as plt

from planner.scores import Validation, kept_models
from stack.runtime.files import save_figure, write_json
from stack.settings.run import RunConfig
from stack.training.summary import NO_CURVE, DemonstrationsUsed, TrainSummary


def plot_training_curve(history: list[Validation], path: Path, title: str) -> None:
    """Mean validation return and collision rate against training steps, titled `title`."""
    figure, (returns, collisions) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for period, marker in (("short", "o"), ("long", "s")):
        points = [v for v in history if v.period == period]
        returns.plot(
            [v.step for v in points], [v.mean_return for v in points], marker, label=f"{period} validation"
        )
        collisions.plot([v.step for v in points], [100 * v.collision_rate for v in points], marker)
    best = kept_models(history)
    returns.plot(
        [v.step for v in best], [v.mean_return for v in best], "k*", markersize=10, label="kept (best)"
    )
    returns.set_title(title, fontsize="medium")
    returns.set_ylabel("mean return")
    collisions.set_ylabel("collision rate [%]")
    collisions.set_xlabel("training steps")
    returns.legend(fontsize="small")
    figure.tight_layout()
    save_figure(figure, path, dpi=110)
    plt.close(figure)


def gradient_steps_per_decision(config: RunConfig) -> float | None:
    """Gradient steps a DDQN / DQN run takes per decision collected; None for a table."""
    train = config.train
    if train.algorithm == "tabular":
        return None
    return train.gradient_steps / (train.parallel * train.train_freq)


def write_training_summary(
    config: RunConfig,
    out: Path,
    history: list[Validation],
    best: Path,
    *,
    steps: int,
    wall_time_s: float,
    interrupted: bool,
    demonstrations: DemonstrationsUsed | None,
) -> TrainSummary:
    """`summary.json` (the best validation and model read off `history` and `best`), `validation.json`
    and `training_curve.png` in `out`; returns the summary."""
    if history:
        train = config.train
        scenarios = ", ".join(train.scenarios) if train.scenarios else (config.scenario or "configured world")
        title = f"{train.algorithm} ({train.network}), seed {config.seed}: validation on {scenarios}"
        plot_training_curve(history, out / "training_curve.png", title)
    kept = kept_models(history)
    summary = TrainSummary(
        algorithm=config.train.algorithm,
        network=config.train.network,
        target_steps=config.train.steps,
        steps=steps,
        wall_time_s=wall_time_s,
        interrupted=interrupted,
        worlds=config.train.worlds,
        gradient_steps_per_decision=gradient_steps_per_decision(config),
        demonstrations=demonstrations,
        best_validation=kept[-1] if kept else None,
        validations=len(history),
        best_model=str(best) if best.is_file() else None,
        training_curve="training_curve.png" if history else NO_CURVE,
    )
    write_json(out / "summary.json", summary.to_json())
    write_json(out / "validation.json", [asdict(v) for v in history])
    return summary
