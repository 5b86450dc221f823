"""What the lookahead sees: its own long, fine grid (the ego's lane and two on each side, with
relative speeds), read back into the vehicles around the ego.

A vehicle marks every cell its footprint overlaps, so a run of occupied cells with one relative
speed is one vehicle (two touching vehicles at one speed read as one long one). Each is placed at
the run's outer cell edges: up to one cell longer than it is, so every gap read is at most the
true gap (never optimistic by more than rounding). The reading is one plain function
(`read_vehicles`) that numba compiles for one observation (`read_scene`) and into the lookahead's
decision over a batch of them (`planner.lookahead`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable

from common.compiled import Kernel
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


class SceneLayout(NamedTuple):
    """A lookahead grid's shape as the compiled reader takes it: cells a lane, the ego's column,
    the cell length [m] and the relative speed that gives grid feature 1 [m/s]."""

    cells: int
    ego_column: int
    cell_length: float
    speed_scale: float


def scene_layout(grid: GridConfig) -> SceneLayout:
    """The `SceneLayout` of `grid` (a `lookahead_grid`)."""
    return SceneLayout(grid.cells, grid.ego_column, grid.cell_length, grid.speed_scale)


def observation_size(grid: GridConfig) -> int:
    """Values in one observation of `grid` (a `lookahead_grid`): presence and relative speed of
    2 REACH + 1 lanes of cells, the ego's speed, the lanes on each side."""
    return 2 * (2 * REACH + 1) * grid.cells + 3


def checked_size(grid: GridConfig, size: int) -> None:
    """ValueError (one line) unless an observation of `size` values is one of `grid`."""
    if size != observation_size(grid):
        raise ValueError(
            f"lookahead agent expected 2 x {2 * REACH + 1} x {grid.cells} grid values, the ego speed and "
            f"2 side-lane values; got {size} values"
        )


def read_scene(grid: GridConfig, observation: np.ndarray) -> Scene:
    """The `Scene` in an observation of `grid` (a `lookahead_grid`); ValueError on another size."""
    observation = np.asarray(observation, dtype=np.float64).reshape(-1)
    checked_size(grid, observation.size)
    room = (2 * REACH + 1) * grid.cells
    lane, centre = np.empty(room, dtype=np.int64), np.empty(room)
    length, velocity = np.empty(room), np.empty(room)
    count, speed, left, right = _read_one(scene_layout(grid), observation, lane, centre, length, velocity)
    return Scene(speed, left, right, lane[:count], centre[:count], length[:count], velocity[:count])


@register_jitable
def read_vehicles(
    layout: SceneLayout,
    observation: np.ndarray,
    lane: np.ndarray,
    centre: np.ndarray,
    length: np.ndarray,
    velocity: np.ndarray,
) -> tuple[int, float, int, int]:
    """(vehicles, ego speed [m/s], lanes on the left, lanes on the right) of one observation of a
    lookahead grid (float64 values): each vehicle's lane relative to the ego's, centre and length
    [m] and speed [m/s] written to the first rows of `lane`, `centre`, `length`, `velocity` (room
    for one a cell), lane by lane from the leftmost seen, rear to front."""
    cells, ego_column, cell_length, speed_scale = (
        layout.cells,
        layout.ego_column,
        layout.cell_length,
        layout.speed_scale,
    )
    size = (2 * REACH + 1) * cells
    speed = observation[2 * size] * MAX_SPEED
    left = round(observation[2 * size + 1] * SIDE_LANES_SEEN)
    right = round(observation[2 * size + 2] * SIDE_LANES_SEEN)
    count = 0
    for shift in range(-min(left, REACH), min(right, REACH) + 1):
        row = (shift + REACH) * cells
        for first in range(cells):
            value = observation[size + row + first] * speed_scale
            if not observation[row + first] > 0:
                continue
            if first > 0 and observation[row + first - 1] > 0:
                if observation[size + row + first - 1] * speed_scale == value:
                    continue
            last = first
            while (
                last + 1 < cells
                and observation[row + last + 1] > 0
                and observation[size + row + last + 1] * speed_scale == value
            ):
                last += 1
            rear = (first - ego_column - 0.5) * cell_length
            front = (last - ego_column + 0.5) * cell_length
            lane[count] = shift
            centre[count] = (rear + front) / 2
            length[count] = front - rear
            velocity[count] = max(speed + value, 0.0)
            count += 1
    return count, speed, left, right


_read_one = Kernel(read_vehicles)
