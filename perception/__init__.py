"""Perception: the occupancy grid around the ego and the paper's encodings, built from a
`records.WorldState` (`stack.world_state(env)` makes one from any highway-env env), and the sensor
model (range, misses, noise, false positives)."""

import common.numba_cache  # noqa: F401  numba's cache folder is set before anything here compiles
from perception.grid import OccupancyGrid, OccupancyGridBuilder
from perception.sensor import SensorConfig, SensorModel
from records import GridConfig, WorldState

__all__ = ["GridConfig", "OccupancyGrid", "OccupancyGridBuilder", "SensorConfig", "SensorModel", "WorldState"]
