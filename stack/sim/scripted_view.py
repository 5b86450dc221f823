"""highway-env's road view of a road built outside an env (`stack.sim.scripted_road`): one highway-v0
env made for drawing only, its road and ego replaced by the ones to draw before each frame."""

from __future__ import annotations

from typing import cast

import gymnasium as gym
import numpy as np
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.road.road import Road
from highway_env.vehicle.kinematics import Vehicle

import stack.sim.highway  # noqa: F401  (sets the headless video driver before pygame starts)

SCREEN_WIDTH, SCREEN_HEIGHT = 600, 150
"""The frame's size [px]."""
SCALING = 5.5
"""[px per m]"""
CENTERING = (0.3, 0.5)
"""Where the ego is drawn, as a fraction of the frame's width and height."""
VIEW = {
    "screen_width": SCREEN_WIDTH,
    "screen_height": SCREEN_HEIGHT,
    "scaling": SCALING,
    "centering_position": list(CENTERING),
}
"""highway-env's viewer settings."""


class RoadView:
    """Draws any highway-env road centred on a vehicle, as `HighwayAdapter.render` does."""

    def __init__(self) -> None:
        self.env = gym.make("highway-v0", render_mode="rgb_array", config=VIEW, disable_env_checker=True)
        self.env.reset(seed=0)

    def render(self, road: Road, vehicle: Vehicle) -> np.ndarray:
        env: AbstractEnv = self.env.unwrapped
        env.road, env.vehicle, env.controlled_vehicles = road, vehicle, [vehicle]
        # gymnasium types render() for every render mode; with rgb_array it is one RGB array
        return cast(np.ndarray, self.env.render())

    @staticmethod
    def scale() -> tuple[float, float]:
        """Pixels per metre, and the ego's x in the frame [px]."""
        return SCALING, CENTERING[0] * SCREEN_WIDTH
