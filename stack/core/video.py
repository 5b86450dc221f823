"""One video frame of a closed-loop episode: a caption, highway-env's road view, and the grid the
agent decides on drawn on the road view's scale under it.

The caption says what runs (agent, controller, world, seed) and the state at this tick: time [s],
ego speed [m/s], lane, and the agent's current command with what became of it (passed, changed by
the safety layer, or ignored while a lane change runs).
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from perception.grid import OccupancyGrid
from perception.plot import TEXT, grid_panel
from records import Command

LINE_PX = 13
"""Height of one caption line [px]."""


def command_text(command: Command, applied: Command | None) -> str:
    """The agent's command and, if it differs, what the maneuver received (`applied`; None when
    the command was ignored because a lane change was running)."""
    if applied is None:
        return f"command {command.name} (ignored: lane change running)"
    if applied is not command:
        return f"command {command.name} -> {applied.name} (safety layer)"
    return f"command {command.name}"


def caption(width: int, lines: list[str]) -> np.ndarray:
    """`lines` of text on a white strip `width` px wide."""
    image = Image.new("RGB", (width, 4 + LINE_PX * len(lines)), "white")
    draw = ImageDraw.Draw(image)
    for number, line in enumerate(lines):
        draw.text((4, 2 + number * LINE_PX), line, fill=TEXT)
    return np.asarray(image)


def video_frame(
    road: np.ndarray,
    grid: OccupancyGrid,
    scale: tuple[float, float],
    lane_width_m: float,
    lines: list[str],
) -> np.ndarray:
    """The caption `lines`, the `road` view (RGB) and the grid panel on its `scale` (px per m, the
    ego's x in the road view [px]), stacked top to bottom."""
    width = road.shape[1]
    panel = grid_panel(grid, width, scale[0], scale[1], lane_width_m)
    return np.vstack([caption(width, lines), road[:, :, :3], panel])
