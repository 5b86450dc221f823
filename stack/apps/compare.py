"""`drivestack compare`: several agents on the same seeded episodes, one table and one bar plot."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
from rich.console import Console

from stack.core.config import RunConfig
from stack.core.episodes import run

COLUMNS = (
    ("collision_rate", "collision rate [%]", 100.0),
    ("mean_speed", "mean speed [m/s]", 1.0),
    ("lane_changes", "lane changes / episode", 1.0),
)


def compare(configs: list[RunConfig], jobs: int = 1, progress: bool = True) -> list[dict]:
    """One summary per config (one config per agent, same episodes and seeds)."""
    return [run(config, progress=progress, jobs=jobs).summary for config in configs]


def compare_and_report(configs: list[RunConfig], out: Path, jobs: int, progress: bool) -> None:
    """Run every config, write `out` (comparison.json, comparison.png), print the table."""
    summaries = compare(configs, jobs=jobs, progress=progress)
    write_comparison(summaries, out)
    Console().print(markdown(summaries), highlight=False)
    Console().print(f"results: {out}")


def write_comparison(summaries: list[dict], out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "comparison.json").write_text(json.dumps(summaries, indent=2) + "\n")
    figure, axes = plt.subplots(1, len(COLUMNS), figsize=(4 * len(COLUMNS), 4))
    names = [s["agent"] for s in summaries]
    for axis, (key, label, scale) in zip(axes, COLUMNS, strict=True):
        axis.bar(names, [scale * s[key] for s in summaries], color="tab:blue")
        axis.set_title(label)
        axis.tick_params(axis="x", rotation=30)
    figure.suptitle(f"{summaries[0]['episodes']} seeded episodes from seed {summaries[0]['seed']}")
    figure.tight_layout()
    figure.savefig(out / "comparison.png", dpi=100)
    plt.close(figure)


def markdown(summaries: list[dict]) -> str:
    lines = [
        "| agent | episodes | collision rate | accuracy | mean speed m/s | lane changes / ep "
        "| masked / ep | aborted / ep |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in summaries:
        accuracy = "n/a" if s["accuracy"] is None else f"{s['accuracy']:.2f} %"
        lines.append(
            f"| {s['agent']} | {s['episodes']} | {100 * s['collision_rate']:.1f} % ({s['collisions']}) | "
            f"{accuracy} | {s['mean_speed']:.2f} | {s['lane_changes']:.2f} | {s['masked_commands']:.2f} | "
            f"{s['aborted_changes']:.2f} |"
        )
    return "\n".join(lines) + "\n"
