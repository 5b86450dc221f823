"""What `drivestack safety` writes and prints: the per-scenario summary (outcome counts, the failures
with their parameters and replay commands, time below R157's minimum following distance), and one
preventability map per scenario type: speed on x, the second parameter on y, one panel per
combination of the others, one colour per outcome."""

from __future__ import annotations

from itertools import product
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch
from rich.console import Console
from rich.table import Table

from stack.assessment.safety_assessment import OUTCOMES, Assessed
from stack.runtime.files import save_figure
from stack.sim.safety_scenarios import PARAMETERS, ScenarioKind

COLOURS = ("#4caf50", "#2196f3", "#e53935", "#9e9e9e")
"""Per outcome (`OUTCOMES` order): green, blue, red, grey."""


def summary(kind: ScenarioKind, points: list[Assessed], replay: str) -> dict[str, Any]:
    """One scenario type's entry of summary.json; `replay` is the command with `{point}` to fill."""
    counts = {outcome: sum(p.outcome == outcome for p in points) for outcome in OUTCOMES}
    failures = [p for p in points if p.outcome == "failure"]
    below = [p.stack.time_below_min_distance_s for p in points]
    return {
        "points": len(points),
        "avoided_by_both": counts["avoided by both"],
        "avoided_only_by_stack": counts["avoided only by the stack"],
        "failures": counts["failure"],
        "unpreventable": counts["unpreventable"],
        "failure_points": [
            {**p.point.parameters, "replay": replay.format(kind=kind, point=p.point.text)} for p in failures
        ],
        "below_r157_min_distance": {
            "points": sum(t > 0 for t in below),
            "max_s": round(max(below, default=0.0), 3),
            "mean_s": round(float(np.mean(below)) if below else 0.0, 3),
        },
        "emergency_brakings": sum(p.stack.emergency_brakings for p in points),
    }


def print_summary(summaries: dict[ScenarioKind, dict[str, Any]], console: Console | None = None) -> None:
    console = console or Console()
    table = Table(title="safety assessment")
    for column in ("scenario", "points", "both avoid", "only stack", "FAILURES", "unpreventable", "< d_min"):
        table.add_column(column, justify="right")
    for kind, s in summaries.items():
        below = s["below_r157_min_distance"]
        table.add_row(
            kind,
            str(s["points"]),
            str(s["avoided_by_both"]),
            str(s["avoided_only_by_stack"]),
            str(s["failures"]),
            str(s["unpreventable"]),
            f"{below['points']} pts, max {below['max_s']:.1f} s",
        )
    console.print(table)
    for kind, s in summaries.items():
        for failure in s["failure_points"]:
            console.print(
                f"failure ({kind}): replay with  {failure['replay']}",
                highlight=False,
                markup=False,
                soft_wrap=True,
            )


def plot_map(kind: ScenarioKind, points: list[Assessed], title: str, path: Path) -> None:
    """The preventability map of one scenario type (see the module docstring)."""
    names = [name for name, _ in PARAMETERS[kind]]
    units = dict(PARAMETERS[kind])
    axes_values = [sorted({p.point.parameters[name] for p in points}) for name in names]
    panel_names, panel_values = names[2:], axes_values[2:]
    rows: list[float | None] = list(panel_values[0]) if len(panel_names) > 1 else [None]
    columns: list[float | None] = list(panel_values[-1]) if panel_names else [None]
    width = max(9.0, 2.6 * len(columns) + 1.5)
    figure, grid = plt.subplots(
        len(rows), len(columns), figsize=(width, 2.4 * len(rows) + 1.6), squeeze=False
    )
    lookup = {p.point.values: OUTCOMES.index(p.outcome) for p in points}
    x_values, y_values = axes_values[0], axes_values[1]
    cmap = ListedColormap(COLOURS)
    for (i, row), (j, column) in product(enumerate(rows), enumerate(columns)):
        axis = grid[i][j]
        image = np.full((len(y_values), len(x_values)), np.nan)
        for (a, x), (b, y) in product(enumerate(x_values), enumerate(y_values)):
            key = (x, y, *(v for v in (row, column) if v is not None))
            image[b, a] = lookup.get(key, np.nan)
        axis.imshow(image, origin="lower", cmap=cmap, vmin=-0.5, vmax=3.5, aspect="auto")
        axis.set_xticks(range(len(x_values)), [f"{x * 3.6:.0f}" for x in x_values], fontsize=7)
        axis.set_yticks(range(len(y_values)), [f"{y:g}" for y in y_values], fontsize=7)
        label = [
            f"{n} = {v:g} {units[n]}"
            for n, v in zip(panel_names, (row, column) if len(panel_names) > 1 else (column,), strict=False)
            if v is not None
        ]
        axis.set_title(", ".join(label), fontsize=8)
        if i == len(rows) - 1:
            axis.set_xlabel("ego speed [km/h]", fontsize=8)
        if j == 0:
            axis.set_ylabel(f"{names[1]} [{units[names[1]]}]", fontsize=8)
    figure.suptitle(title)
    figure.legend(
        handles=[Patch(color=c, label=o) for c, o in zip(COLOURS, OUTCOMES, strict=True)],
        loc="lower center",
        ncol=4,
        fontsize=9,
    )
    figure.tight_layout(rect=(0, 0.06, 1, 0.94))
    save_figure(figure, path, 110)
    plt.close(figure)
