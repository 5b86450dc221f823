"""The pictures and the table of `drivestack track`: per speed, the controllers' lane changes
overlaid (lateral offset, steering, lateral acceleration and jerk); one table row per controller,
road, plant and speed."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib.pyplot as plt
import numpy as np
from rich.console import Console
from rich.table import Table

if TYPE_CHECKING:
    from stack.apps.track import Maneuver


def print_tracking(maneuvers: list[Maneuver]) -> None:
    """One row per controller, road, plant and speed: left and right changes averaged."""
    table = Table(title="lane changes (left / right averaged)")
    for column in (
        "controller",
        "road",
        "plant",
        "speed",
        "duration s",
        "overshoot cm",
        "RMS cm",
        "max cm",
        "peak a_y",
        "peak jerk",
        "solve p95 ms",
        "fallbacks",
    ):
        table.add_column(column, justify="right")
    groups: dict[tuple[str, str, str, float], list[Maneuver]] = {}
    for m in maneuvers:
        groups.setdefault((m.controller, m.road, m.plant, m.speed), []).append(m)
    for (name, road, plant, speed), group in groups.items():

        def mean(field: str, group: list[Maneuver] = group) -> float:
            values = [getattr(m, field) for m in group if getattr(m, field) is not None]
            return sum(values) / len(values) if values else float("nan")

        table.add_row(
            name,
            road,
            plant,
            f"{speed:g}",
            f"{mean('duration_s'):.2f}",
            f"{100 * mean('overshoot_m'):.1f}",
            f"{100 * mean('rms_error_m'):.2f}",
            f"{100 * mean('max_error_m'):.1f}",
            f"{mean('peak_lat_accel'):.2f}",
            f"{mean('peak_lat_jerk'):.2f}",
            f"{max(m.solve_ms_p95 for m in group):.2f}",
            str(sum(m.fallbacks for m in group)),
        )
    Console(width=160).print(table)


def plot_speed(maneuvers: list[Maneuver], path: Path, speed: float) -> None:
    figure, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    for m in maneuvers:
        t = m.trace["time"]
        axes[0].plot(t, m.trace["d"], label=m.controller)
        axes[1].plot(t, np.degrees(m.trace["steering"]))
        axes[2].plot(t, m.trace["lat_accel"])
        axes[3].plot(t, m.trace["lat_jerk"])
    if maneuvers:
        axes[0].plot(maneuvers[0].trace["time"], maneuvers[0].trace["d_ref"], "k--", lw=1, label="reference")
    for axis, label in zip(
        axes,
        ("lateral offset [m]", "steering [deg]", "a_y, 500 ms avg [m/s²]", "jerk, 500 ms avg [m/s³]"),
        strict=True,
    ):
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize="small")
    axes[0].set_title(f"lane change at {speed:g} m/s (straight road, kinematic plant)")
    axes[-1].set_xlabel("time [s]")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)
