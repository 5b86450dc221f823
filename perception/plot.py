"""Pictures of the grid: a pixel panel for videos and a matplotlib figure over the road."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Rectangle

from perception.grid import OccupancyGrid
from records import WorldState

EMPTY = (235, 235, 235)
OCCUPIED = (220, 60, 50)
EGO = (50, 110, 220)
GRID_LINE = (160, 160, 160)
ROW_HEIGHT_PX = 16


def grid_panel(grid: OccupancyGrid, width: int) -> np.ndarray:
    """The grid as an RGB image `width` pixels wide, one row per lane, top row = row 0 (left);
    occupied cells red, the ego's cell blue. For side-by-side video frames."""
    rows, cells = grid.cells.shape
    image = np.empty((rows, cells, 3), dtype=np.uint8)
    image[:] = EMPTY
    image[grid.cells > 0] = OCCUPIED
    image[grid.ego_row, grid.config.ego_column] = EGO
    column_px = max(1, width // cells)
    scaled = np.repeat(np.repeat(image, ROW_HEIGHT_PX, axis=0), column_px, axis=1)
    scaled[::ROW_HEIGHT_PX] = GRID_LINE
    scaled[:, ::column_px] = GRID_LINE
    panel = np.full((rows * ROW_HEIGHT_PX, width, 3), 255, dtype=np.uint8)
    panel[:, : scaled.shape[1]] = scaled[:, :width]
    return panel


def plot_grid_over_road(world: WorldState, grid: OccupancyGrid, path: Path) -> None:
    """Vehicles (lane frame, relative to the ego) with the grid cells they occupy shaded."""
    config = grid.config
    figure, axis = plt.subplots(figsize=(11, 1.6 + 0.6 * world.lanes_count))
    half_lane = world.lane_width / 2
    seen = {grid.row_lane(row) for row in range(grid.cells.shape[0])}
    left, right = (
        -(config.cells_behind + 0.5) * config.cell_length,
        (config.cells_ahead - 0.5) * config.cell_length,
    )
    for lane in range(world.lanes_count):
        if lane not in seen:
            centre = world.lane_offsets[lane]
            axis.add_patch(
                Rectangle(
                    (left, centre - half_lane),
                    right - left,
                    2 * half_lane,
                    facecolor="0.85",
                    hatch="//",
                    edgecolor="0.6",
                    lw=0,
                )
            )
    for row in range(grid.cells.shape[0]):
        lane = grid.row_lane(row)
        if not 0 <= lane < world.lanes_count:
            continue
        centre = world.lane_offsets[lane]
        for column in range(config.cells):
            x = (column - config.ego_column - 0.5) * config.cell_length
            occupied = grid.cells[row, column] > 0
            axis.add_patch(
                Rectangle(
                    (x, centre - half_lane),
                    config.cell_length,
                    2 * half_lane,
                    facecolor="tab:red" if occupied else "none",
                    alpha=0.25,
                    edgecolor="0.7",
                    lw=0.5,
                )
            )
    for lane_edge in np.append(world.lane_offsets - half_lane, world.lane_offsets[-1] + half_lane):
        axis.axhline(lane_edge, color="0.3", lw=0.8)
    rel_s = world.s - world.s[0]
    for row in range(world.count):
        axis.add_patch(
            Rectangle(
                (rel_s[row] - world.length[row] / 2, world.d[row] - world.width[row] / 2),
                world.length[row],
                world.width[row],
                facecolor="tab:blue" if row == 0 else "tab:gray",
                edgecolor="black",
                lw=0.6,
            )
        )
    axis.set_xlim(
        -(config.cells_behind + 1) * config.cell_length, (config.cells_ahead + 1) * config.cell_length
    )
    axis.set_ylim(world.lane_offsets[-1] + half_lane + 1, world.lane_offsets[0] - half_lane - 1)
    axis.add_patch(
        Rectangle(
            (left, world.lane_offsets[0] - half_lane),
            right - left,
            world.lane_offsets[-1] - world.lane_offsets[0] + 2 * half_lane,
            fill=False,
            edgecolor="black",
            lw=1.2,
            linestyle="--",
        )
    )
    axis.set_yticks(world.lane_offsets, [f"lane {lane}" for lane in range(world.lanes_count)])
    axis.set_xlabel("longitudinal distance from the ego [m]")
    axis.set_aspect("equal")
    axis.set_title(
        f"occupancy grid the agent sees at t = {world.time:.1f} s (ego in lane {grid.ego_lane}; "
        f"{config.cell_length:g} m cells, {config.lanes} rows)"
    )
    key = [
        Rectangle((0, 0), 1, 1, facecolor="tab:red", alpha=0.25, edgecolor="0.7"),
        Rectangle((0, 0), 1, 1, facecolor="none", edgecolor="0.7"),
        Rectangle((0, 0), 1, 1, facecolor="0.85", hatch="//", edgecolor="0.6"),
        Rectangle((0, 0), 1, 1, facecolor="tab:blue", edgecolor="black"),
        Rectangle((0, 0), 1, 1, facecolor="tab:gray", edgecolor="black"),
    ]
    names = ["occupied cell", "free cell", "lane outside the agent's grid", "ego", "other vehicle"]
    axis.legend(
        key, names, loc="upper center", bbox_to_anchor=(0.5, -0.35), ncol=5, fontsize="small", frameon=False
    )
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
