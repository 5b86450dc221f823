"""The `run --video` GIF: a caption with time, speed and command over the road view, and the grid
panel on the road view's scale with lane labels and a distance axis."""

import imageio.v2 as imageio
import numpy as np

from perception.grid import GridConfig, OccupancyGridBuilder
from perception.plot import AXIS_PX, CAPTION_PX, OCCUPIED, grid_panel
from records import Command
from stack.loop.video import LINE_PX, command_text
from tests.helpers import scene
from tests.test_cli import run_tiny

ROAD_HEIGHT_PX = 150
"""highway-env's default screen height."""


def test_video_frames_carry_a_changing_caption_over_the_road_and_the_grid(tmp_path):
    result, out = run_tiny(tmp_path, "--episodes", "1", "--seed", "3", "--video")
    assert result.exit_code == 0, result.output
    frames = [np.asarray(frame)[:, :, :3] for frame in imageio.mimread(out / "episode0.gif")]
    assert len(frames) > 1
    assert all(len(np.unique(frame.reshape(-1, 3), axis=0)) > 10 for frame in frames), "never blank"
    caption_px = 4 + 2 * LINE_PX
    rows = (frames[0].shape[0] - caption_px - ROAD_HEIGHT_PX - CAPTION_PX - AXIS_PX) / 22
    assert rows == 5, "caption, road view and the DDQN's 5-row grid (2 lanes each side), 22 px (4 m) a row"
    captions = [frame[:caption_px] for frame in frames]
    assert not np.array_equal(captions[0], captions[-1]), "the time in the caption moves on"
    assert all(np.any(caption != 255) for caption in captions), "the caption has text"


def test_the_grid_panel_draws_a_car_where_the_road_view_does():
    world = scene(3, (100.0, 1), [(120.0, 0.0)])  # a car 20 m ahead in lane 0
    grid = OccupancyGridBuilder(GridConfig(cell_length=5.0, cells_ahead=9, cells_behind=2)).build(world)
    px_per_m, ego_x = 5.5, 180.0
    panel = grid_panel(grid, 600, px_per_m, ego_x, world.lane_width)
    lane_px = round(world.lane_width * px_per_m)
    lane0 = panel[CAPTION_PX + lane_px // 2]
    red = np.flatnonzero(np.all(lane0 == OCCUPIED, axis=1))
    assert abs(red.mean() - (ego_x + 20 * px_per_m)) <= 2, "the car's cell centred 20 m ahead"
    assert 5 * px_per_m - 3 <= len(red) <= 5 * px_per_m + 1, "one 5 m cell wide"
    assert panel.shape == (CAPTION_PX + 3 * lane_px + AXIS_PX, 600, 3)


def test_command_text_says_what_became_of_the_command():
    assert command_text(Command.LEFT, Command.LEFT) == "command LEFT"
    assert command_text(Command.LEFT, Command.STAY) == "command LEFT -> STAY (safety layer)"
    assert command_text(Command.RIGHT, None) == "command RIGHT (ignored: lane change running)"


def test_the_road_view_is_drawn_when_the_environment_asks_for_the_dummy_driver(tmp_path):
    """Issue 52 (7): with SDL_VIDEODRIVER=dummy highway-env skips drawing; the adapter renders
    offscreen instead, so the GIF's road view is not black."""
    import os
    import subprocess
    import sys

    from tests.test_cli import tiny_config_file

    out = tmp_path / "out"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), "--episodes", "1", "--video", "--no-progress"]
    environment = os.environ | {"SDL_VIDEODRIVER": "dummy"}
    done = subprocess.run(
        [sys.executable, "-m", "stack", *arguments, "--out", str(out)], env=environment, capture_output=True
    )
    assert done.returncode == 0, done.stderr.decode()
    frame = np.asarray(imageio.mimread(out / "episode0.gif")[0])[:, :, :3]
    road = frame[4 + 2 * LINE_PX :][:ROAD_HEIGHT_PX]
    assert road.mean() > 60 and len(np.unique(road.reshape(-1, 3), axis=0)) >= 4, "drawn, not black"
