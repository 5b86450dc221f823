"""Where a recording draws things, in world coordinates [m], many points at once: the vehicles'
footprints, the cells of a grid, lines along a lane (`stack.rrd.recording_file` writes them)."""

from __future__ import annotations

import numpy as np

from perception.grid import OccupancyGrid
from records import WorldState
from records.world import Lane

CLOSED_BOX = (np.array([1.0, 1.0, -1.0, -1.0, 1.0]), np.array([1.0, -1.0, -1.0, 1.0, 1.0]))
"""A rectangle's corners as (along, across) signs, the first repeated to close it."""


def lane_points(lane: Lane, s: np.ndarray, d: np.ndarray) -> np.ndarray:
    """`lane.position(s, d)` for every pair: (points, 2) [m]. A straight lane (highway-env's
    `StraightLane`: start, direction and direction_lateral vectors) in one step, others point by
    point."""
    s, d = np.asarray(s, dtype=float), np.asarray(d, dtype=float)
    start = getattr(lane, "start", None)
    along = getattr(lane, "direction", None)
    across = getattr(lane, "direction_lateral", None)
    if all(isinstance(v, np.ndarray) and v.shape == (2,) for v in (start, along, across)):
        return start + s[:, None] * along + d[:, None] * across
    return np.array([lane.position(float(a), float(b)) for a, b in zip(s, d, strict=True)]).reshape(-1, 2)


def box_corners(
    position: np.ndarray, heading: np.ndarray, length: np.ndarray, width: np.ndarray
) -> np.ndarray:
    """Footprints as closed polygons: (boxes, 5, 2) float32 [m] from centres (boxes, 2) [m],
    headings [rad], lengths and widths [m]."""
    cos, sin = np.cos(heading)[:, None], np.sin(heading)[:, None]
    dx = CLOSED_BOX[0][None, :] * (length / 2)[:, None]
    dy = CLOSED_BOX[1][None, :] * (width / 2)[:, None]
    x = position[:, 0:1] + dx * cos - dy * sin
    y = position[:, 1:2] + dx * sin + dy * cos
    return np.stack([x, y], axis=2).astype(np.float32)


def grid_cells(world: WorldState, grid: OccupancyGrid) -> np.ndarray:
    """The occupied cells of `grid` (built on `world`) as closed polygons: (cells, 5, 2) float32
    [m]; a cell spans its lane's width and `cell_length` along the road, ego-relative."""
    config = grid.config
    rows, columns = np.nonzero(grid.cells > 0)
    lanes = np.array([grid.row_lane(int(row)) for row in rows], dtype=int)
    on_road = (lanes >= 0) & (lanes < world.lanes_count)
    lanes, columns = lanes[on_road], columns[on_road]
    start = float(world.s[0]) + (columns - config.ego_column - 0.5) * config.cell_length
    centre = world.lane_offsets[lanes] if lanes.size else np.zeros(0)
    s = start[:, None] + (CLOSED_BOX[0][None, :] + 1) / 2 * config.cell_length
    d = centre[:, None] + CLOSED_BOX[1][None, :] * world.lane_width / 2
    points = lane_points(world.lanes[0], s.reshape(-1), d.reshape(-1))
    return points.reshape(-1, 5, 2).astype(np.float32)
