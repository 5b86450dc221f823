"""What the lookahead sees: its own long, fine grid (the ego's lane and two on each side, with
relative speeds), read back into the vehicles around the ego.

A vehicle marks every cell its footprint overlaps, so a run of occupied cells with one relative
speed is one vehicle (two touching vehicles at one speed read as one long one). Each is placed at
the run's outer cell edges: up to one cell longer than it is, so every gap read is at most the
true gap (never optimistic by more than rounding).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from records import MAX_SPEED, SIDE_LANES_SEEN, GridConfig

CELL_M = 2.0
"""The lookahead grid's cell length [m]."""
CELLS_AHEAD = 100
"""Its cells ahead, the ego's included (200 m: a stopped car is seen 6.7 s ahead at 30 m/s)."""
CELLS_BEHIND = 30
"""Its cells behind (60 m: a car 10 m/s faster is seen 6 s before it reaches the ego)."""
SPEED_SCALE = MAX_SPEED
"""Relative speed giving grid feature 1 [m/s]: a stopped car is not clipped at any ego speed."""
REACH = SIDE_LANES_SEEN
"""Lanes seen on each side of the ego's (2: the lane a change leads to, and the one beyond it)."""
EGO_LENGTH = 5.0
"""The ego's length [m] (highway-env's vehicles'): the grid shows the others only."""


def lookahead_grid(grid: GridConfig) -> GridConfig:
    """The grid the lookahead decides on: the run's, reshaped to ego-relative rows (`REACH` lanes
    on each side), `CELL_M` cells from `CELLS_BEHIND` behind to `CELLS_AHEAD` ahead, footprints,
    relative and ego speeds, and the lanes on each side (`sides`: any lane count)."""
    return grid.model_copy(
        update={
            "lanes": "ego",
            "lateral_reach": REACH,
            "cell_length": CELL_M,
            "cells_ahead": CELLS_AHEAD,
            "cells_behind": CELLS_BEHIND,
            "footprint": True,
            "features": ("relative_speed", "ego_speed"),
            "speed_scale": SPEED_SCALE,
            "lane_code": "sides",
        }
    )


@dataclass(frozen=True)
class Scene:
    """The ego's speed [m/s], the lanes on its left and right (up to `REACH`), and the vehicles
    seen: lane relative to the ego's (-1 the next on the left, 0 its own, +1 the next on the right,
    +-2 beyond), centre along the road relative to the ego's [m], length [m], speed [m/s]."""

    speed: float
    left: int
    right: int
    lane: np.ndarray
    centre: np.ndarray
    length: np.ndarray
    velocity: np.ndarray


def read_scene(grid: GridConfig, observation: np.ndarray) -> Scene:
    """The `Scene` in an observation of `grid` (a `lookahead_grid`); ValueError on another size."""
    observation = np.asarray(observation, dtype=np.float64).reshape(-1)
    cells, rows = grid.cells, 2 * REACH + 1
    size = rows * cells
    if observation.size != 2 * size + 3:
        raise ValueError(
            f"lookahead agent expected 2 x {rows} x {cells} grid values, the ego speed and 2 side-lane "
            f"values; got {observation.size} values"
        )
    presence = observation[:size].reshape(rows, cells) > 0
    relative = observation[size : 2 * size].reshape(rows, cells) * grid.speed_scale
    speed = float(observation[2 * size]) * MAX_SPEED
    left, right = (round(float(value) * SIDE_LANES_SEEN) for value in observation[2 * size + 1 :])
    lanes, centres, lengths, speeds = [], [], [], []
    for shift in range(-min(left, REACH), min(right, REACH) + 1):
        row = shift + REACH
        first, last = _runs(presence[row], relative[row])
        rear = (first - grid.ego_column - 0.5) * grid.cell_length
        front = (last - grid.ego_column + 0.5) * grid.cell_length
        lanes.append(np.full(first.size, shift, dtype=np.int64))
        centres.append((rear + front) / 2)
        lengths.append(front - rear)
        speeds.append(np.maximum(speed + relative[row, first], 0.0))
    return Scene(
        speed,
        left,
        right,
        np.concatenate(lanes),
        np.concatenate(centres),
        np.concatenate(lengths),
        np.concatenate(speeds),
    )


def _runs(occupied: np.ndarray, value: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first, last) columns of each run of occupied cells that share one `value`."""
    inside = np.concatenate([[False], occupied, [False]])
    level = np.concatenate([[np.nan], value, [np.nan]])
    changed = (level[1:] != level[:-1]) | (inside[1:] != inside[:-1])
    starts = np.flatnonzero(changed[:-1] & inside[1:-1])
    ends = np.flatnonzero(changed[1:] & inside[1:-1])
    return starts, ends
