"""The video of a closed-loop episode, drawn from the loop's tick records outside the tick: each
frame a caption, highway-env's road view, and the grid the agent decides on drawn on the road
view's scale under it.

The caption says what runs (agent, controller, world, seed) and the state at this tick: time [s],
ego speed [m/s], lane, and the agent's current command with what became of it (passed, changed by
the safety layer, or ignored while a lane change runs).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from PIL import Image, ImageDraw

from perception.grid import OccupancyGrid
from perception.plot import TEXT, grid_panel
from records import Command
from stack.loop.loop_records import Tick

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


class RenderedRoad(Protocol):
    """What the video draws from: a plant that renders its road (`stack.loop.closed_loop.Plant`)."""

    @property
    def rendering(self) -> bool: ...

    def render(self) -> np.ndarray: ...

    def render_scale(self) -> tuple[float, float]: ...


class Video:
    """An episode's frames, appended to `frames`: every `every`-th tick (the `every`-th, the
    2 `every`-th, ...) while the plant renders, drawn right after the tick, before the next."""

    def __init__(self, frames: list[np.ndarray], plant: RenderedRoad, title: str, every: int) -> None:
        """`title` is the caption's first line (what runs, in which world, on which seed)."""
        self.frames, self.plant, self.title, self.every = frames, plant, title, every
        self.ticks = 0

    def add(self, tick: Tick, grid: OccupancyGrid | None, command: Command, applied: Command | None) -> None:
        """Count `tick` and draw it when its frame is due: the state it led to, the agent's last
        `command` and what became of it (`applied`), and the last decision's `grid`."""
        self.ticks += 1
        if self.ticks % self.every or not self.plant.rendering:
            return
        assert grid is not None, "frames are drawn after the first perceive()"
        world = tick.world
        lane = f"lane {tick.lane}" + (f" -> {tick.target}" if tick.changing_lane else "")
        state = f"t = {world.time:5.1f} s   v = {world.speed[0]:5.2f} m/s   {lane}   "
        lines = [self.title, state + command_text(command, applied)]
        road = self.plant.render()
        self.frames.append(video_frame(road, grid, self.plant.render_scale(), world.lane_width, lines))
