"""The pictures and the table of `drivestack track`: one figure per road, plant and speed (the
controllers' left changes overlaid), one table row per controller, road, plant and speed with the
worst of the left and right change (the table `benchmarks/tracking_table.py` prints too)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib.pyplot as plt
import numpy as np
from rich.console import Console
from rich.table import Table

from stack.runtime.files import save_figure

if TYPE_CHECKING:
    from stack.apps.track_record import TrackedLaneChange

COLUMNS = (
    "controller",
    "road",
    "plant",
    "speed m/s",
    "duration s",
    "overshoot cm",
    "RMS cm",
    "max cm",
    "peak a_y m/s²",
    "peak jerk m/s³",
    "solve p50 / p95 ms",
    "fallbacks",
)
STYLES = {
    "pid": {"color": "tab:blue", "ls": "-"},
    "mpc": {"color": "tab:orange", "ls": "--"},
    "pure-pursuit": {"color": "tab:green", "ls": "-."},
    "stanley": {"color": "tab:red", "ls": "-"},
    "lqr": {"color": "tab:purple", "ls": "--"},
    "builtin": {"color": "tab:gray", "ls": ":"},
}
"""One colour and line style per built-in controller, so they stay apart where they overlap (plug-ins
take matplotlib's next colours)."""


def speed_label(speeds: tuple[float, float]) -> str:
    """`20` for a constant speed, `20-5` for a maneuver from 20 m/s with the cruise set to 5."""
    start, end = speeds
    return f"{start:g}" if start == end else f"{start:g}-{end:g}"


def worst_cases(records: list[dict[str, Any]]) -> list[list[str]]:
    """Table rows (`COLUMNS`) of `tracking.json` records: per controller, road, plant and speed,
    the worse of the left and right change in every figure ("not settled" when either never
    settles within 0.1 m; "below min. speed" when no lane change starts, the rest is then lane
    keeping)."""
    groups: dict[tuple[str, str, str, tuple[float, float]], list[dict[str, Any]]] = {}
    for r in records:
        speeds = (r["speed"], r.get("end_speed", r["speed"]))
        groups.setdefault((r["controller"], r["road"], r["plant"], speeds), []).append(r)
    rows = []
    for (name, road, plant, speeds), group in groups.items():

        def worst(key: str, scale: float = 1.0, digits: int = 2, group: list = group) -> str:
            return f"{scale * max(r[key] for r in group):.{digits}f}"

        durations = [r["duration_s"] for r in group]
        duration = "not settled" if None in durations else f"{max(durations):.2f}"
        if not all(r.get("started", True) for r in group):
            duration = "below min. speed"
        rows.append(
            [
                name,
                road,
                plant,
                speed_label(speeds),
                duration,
                worst("overshoot_m", 100, 1),
                worst("rms_error_m", 100),
                worst("max_error_m", 100, 1),
                worst("peak_lat_accel"),
                worst("peak_lat_jerk"),
                f"{worst('solve_ms_p50')} / {worst('solve_ms_p95')}",
                str(sum(r["fallbacks"] for r in group)),
            ]
        )
    return rows


def markdown_table(records: list[dict[str, Any]]) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(row) + " |" for row in worst_cases(records)]
    return "\n".join(lines) + "\n"


def print_tracking(maneuvers: list[TrackedLaneChange]) -> None:
    table = Table(title="lane changes (worst of left and right)")
    for column in COLUMNS:
        table.add_column(column, justify="right")
    for row in worst_cases([m.record() for m in maneuvers]):
        table.add_row(*row)
    Console(width=170).print(table)


def plot_maneuvers(maneuvers: list[TrackedLaneChange], path: Path) -> None:
    """Lateral offset and reference, tracking error, steering, a_y and jerk of the maneuvers of
    one road, plant and speed. highway-env's built-in change, whose error is metres where the
    others' are centimetres, is drawn in the offset panel only and on its own error axis."""
    if not maneuvers:
        return
    first = maneuvers[0]
    figure, axes = plt.subplots(5, 1, figsize=(9, 11), sharex=True)
    builtin_error = None
    for m in maneuvers:
        t, style = m.trace["time"], STYLES.get(m.controller, {})
        error_cm = 100 * (np.array(m.trace["d"]) - np.array(m.trace["d_ref"]))
        axes[0].plot(t, m.trace["d"], label=m.controller, **style)
        if m.controller == "builtin":
            builtin_error = axes[1].twinx()
            builtin_error.plot(t, error_cm / 100, **style)
            builtin_error.set_ylabel("built-in error [m]", color=style.get("color"))
            continue
        axes[1].plot(t, error_cm, **style)
        axes[2].plot(t, np.degrees(m.trace["steering"]), **style)
        axes[3].plot(t, m.trace["lat_accel"], **style)
        axes[4].plot(t, m.trace["lat_jerk"], **style)
    axes[0].plot(first.trace["time"], first.trace["d_ref"], "k", lw=0.8, alpha=0.6, label="reference")
    labels = (
        "lateral offset [m]",
        "tracking error [cm]",
        "steering [deg]",
        "a_y, 500 ms avg [m/s²]",
        "jerk, 500 ms avg [m/s³]",
    )
    for axis, label in zip(axes, labels, strict=True):
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize="small", loc="lower right")
    axes[0].set_title(
        f"left lane change at {speed_label((first.speed, first.end_speed))} m/s, road {first.road}, "
        f"{first.plant} plant\n"
        "built-in change (if run): offset panel and right-hand error axis",
        fontsize="medium",
    )
    axes[-1].set_xlabel("time [s]")
    figure.tight_layout()
    save_figure(figure, path, dpi=90)
    plt.close(figure)
