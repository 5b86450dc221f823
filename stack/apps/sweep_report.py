"""The report of a sweep (`stack.apps.sweep`), read from the trials' own run folders: trials.csv and
trials.md (one row per trial: its parameters, status and best long validation), sweep.png (every
trial's long validations over training steps, and each trial's kept score), the best trial's model
as best_model.npz, and summary.json."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt

from stack.runtime.files import replacing, save_figure, write_csv, write_json, write_text
from stack.settings.sweep import SweepFile
from stack.training.summary import TrainSummary

TRIALS = "trials"
FIGURES = ("collision_rate", "mean_return", "mean_speed")
"""A kept validation's figures in the table (collision rate as a fraction, mean speed in m/s)."""


def trial_row(sweep: SweepFile, folder: Path, params: dict, metrics: dict, error: object) -> dict[str, Any]:
    """One trial: id, status, its parameters, steps trained and its kept model's validation (an
    unfinished trial has no summary yet: its steps are those Tune last heard of)."""
    trial = str(metrics.get("trial_id", "?"))
    summary_path = folder / TRIALS / trial / "summary.json"
    summary = TrainSummary.from_json(json.loads(summary_path.read_text())) if summary_path.is_file() else None
    best = summary.best_validation if summary is not None else None
    status = "error" if error else "finished" if metrics.get("finished") else "unfinished"
    row: dict[str, Any] = {"trial": trial, "status": status}
    row |= {key: params.get(key) for key in sweep.space}
    row |= {"steps": summary.steps if summary is not None else metrics.get("step", 0)}
    row |= {"best_step": best.step if best is not None else None}
    row |= {figure: getattr(best, figure) if best is not None else None for figure in FIGURES}
    return row | {"score": getattr(best, sweep.metric) if best is not None else None}


def best_row(rows: list[dict[str, Any]], mode: str) -> dict[str, Any] | None:
    """The trial whose kept model scores best (`mode` max or min; the first one on a tie)."""
    scored = [row for row in rows if row["score"] is not None]
    if not scored:
        return None
    sign = 1.0 if mode == "max" else -1.0
    return max(scored, key=lambda row: sign * row["score"])


def markdown(rows: list[dict[str, Any]], best: dict[str, Any] | None) -> str:
    """The trials as a markdown table, the best one marked."""
    columns = list(rows[0])
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in rows:
        cells = [f"{v:.4g}" if isinstance(v, float) else "" if v is None else str(v) for v in row.values()]
        cells[0] += " (best)" if row is best else ""
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_sweep(
    rows: list[dict[str, Any]], best: dict[str, Any] | None, folder: Path, sweep: SweepFile
) -> None:
    """sweep.png: every trial's long validations against training steps (left), its kept score
    (right); the legend gives each trial's parameters."""
    metric = sweep.metric
    figure, (curves, bars) = plt.subplots(1, 2, figsize=(12, 4.5), gridspec_kw={"width_ratios": [2, 1]})
    for row in rows:
        history_path = folder / TRIALS / row["trial"] / "validation.json"
        history = json.loads(history_path.read_text()) if history_path.is_file() else []
        points = [v for v in history if v["period"] == "long"]
        width = 2.5 if row is best else 1.0
        params = ", ".join(f"{key.rsplit('.', 1)[-1]}={row[key]}" for key in sweep.space)
        steps, values = [v["step"] for v in points], [v[metric] for v in points]
        curves.plot(steps, values, "o-", lw=width, label=f"{row['trial']}: {params}")
    curves.set_xlabel("training steps")
    curves.set_ylabel(f"long validation {metric}")
    curves.legend(fontsize="small")
    names = [row["trial"] for row in rows]
    scores = [row["score"] if row["score"] is not None else 0.0 for row in rows]
    colours = ["tab:orange" if row is best else "tab:blue" for row in rows]
    bars.bar(names, scores, color=colours)
    bars.set_ylabel(f"kept model's {metric}")
    bars.set_xlabel("trial (orange: best)")
    bars.tick_params(axis="x", rotation=30)
    figure.suptitle(f"sweep: {len(rows)} trials, metric {metric} of the long real-time validation")
    figure.tight_layout()
    save_figure(figure, folder / "sweep.png", dpi=100)
    plt.close(figure)


def report(sweep: SweepFile, folder: Path, trials: list[tuple[dict, dict, object]]) -> bool:
    """Write and print the sweep's report from Tune's (params, last metrics, error) per trial;
    True when some trial is unfinished (the sweep can be resumed)."""
    rows = [trial_row(sweep, folder, params, metrics, error) for params, metrics, error in trials]
    rows.sort(key=lambda row: row["trial"])
    best = best_row(rows, sweep.mode)
    write_csv(folder / "trials.csv", rows)
    table = markdown(rows, best)
    write_text(folder / "trials.md", table)
    plot_sweep(rows, best, folder, sweep)
    best_model = folder / TRIALS / best["trial"] / "best.npz" if best else None
    if best_model and best_model.is_file():
        with replacing(folder / "best_model.npz") as copy:
            shutil.copyfile(best_model, copy)
    unfinished = any(row["status"] != "finished" for row in rows)
    summary = {
        "metric": sweep.metric,
        "mode": sweep.mode,
        "trials": len(rows),
        "finished": sum(row["status"] == "finished" for row in rows),
        "interrupted": unfinished,
        "best": best,
        "best_model": "best_model.npz" if (folder / "best_model.npz").is_file() else None,
    }
    write_json(folder / "summary.json", summary)
    print(table, end="")
    resume = f" (unfinished trials: `drivestack sweep --resume {folder}` continues them)"
    print(f"results: {folder}" + (resume if unfinished else ""))
    return unfinished
