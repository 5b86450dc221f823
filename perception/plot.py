"""Pictures of the grid: a panel on the road view's scale for videos, a matplotlib figure over the road."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Rectangle
from PIL import Image, ImageDraw

from perception.grid import OccupancyGrid
from records import WorldState

EMPTY = (235, 235, 235)
OCCUPIED = (220, 60, 50)
EGO = (50, 110, 220)
GRID_LINE = (160, 160, 160)
TEXT = (20, 20, 20)
CAPTION_PX = 14
"""Height of the panel's title strip [px]."""
AXIS_PX = 28
"""Height of the distance axis under the cells [px]."""
TICK_M = 10
"""Distance between axis ticks [m]; every second one is labelled."""


def grid_panel(
    grid: OccupancyGrid, width: int, px_per_m: float, ego_x_px: float, lane_width_m: float
) -> np.ndarray:
    """The grid as an RGB image on the road view's scale, for video frames under highway-env's
    render: `px_per_m` [px/m] along and across, the ego's cell centred at `ego_x_px` (where the
    road view draws the ego), one `lane_width_m` tall row per grid row, row 0 on top like lane 0
    on the road. Occupied cells red (rows beyond the road all red, as the agent sees them), the
    ego's cell blue; rows labelled by lane ("off road" beyond the road), a distance axis
    in metres from the ego underneath, a title with the cell size."""
    config = grid.config
    rows = grid.cells.shape[0]
    row_px = max(8, round(lane_width_m * px_per_m))
    cell_px = config.cell_length * px_per_m
    image = Image.new("RGB", (width, CAPTION_PX + rows * row_px + AXIS_PX), "white")
    draw = ImageDraw.Draw(image)
    draw.text(
        (4, 1),
        f"grid the agent sees (red occupied, blue ego): {config.cell_length:g} m cells, {rows} rows, "
        "road's scale",
        fill=TEXT,
    )
    for row in range(rows):
        top = CAPTION_PX + row * row_px
        for column in range(config.cells):
            left = ego_x_px + (column - config.ego_column - 0.5) * cell_px
            ego = row == grid.ego_row and column == config.ego_column
            colour = EGO if ego else OCCUPIED if grid.cells[row, column] > 0 else EMPTY
            draw.rectangle((left, top, left + cell_px, top + row_px), fill=colour, outline=GRID_LINE)
        lane = grid.row_lane(row)
        label = f"lane {lane}" if 0 <= lane < grid.lanes_count else "off road"
        draw.text((2, top + row_px / 2 - 6), label, fill=TEXT)
    axis = CAPTION_PX + rows * row_px
    first = -(config.cells_behind + 0.5) * config.cell_length
    last = (config.cells_ahead - 0.5) * config.cell_length
    draw.line((ego_x_px + first * px_per_m, axis, ego_x_px + last * px_per_m, axis), fill=TEXT)
    for metres in range(int(np.ceil(first / TICK_M)) * TICK_M, int(last) + 1, TICK_M):
        x = ego_x_px + metres * px_per_m
        draw.line((x, axis, x, axis + 3), fill=TEXT)
        if metres % (2 * TICK_M) == 0:
            draw.text((x, axis + 4), f"{metres}", fill=TEXT, anchor="ma")
    draw.text((width - 4, axis + 15), "longitudinal distance from the ego [m]", fill=TEXT, anchor="ra")
    return np.asarray(image)


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
