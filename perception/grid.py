"""Occupancy grid of the ego's surroundings and the paper's encodings.

Rows are lanes (absolute: row = lane index, as the paper), columns are longitudinal cells of
`cell_length` metres, ego-relative in x: column `cells_behind` is the ego's own cell
([-L/2, L/2) around the ego's centre), the `cells_ahead` columns from there on are the paper's
line of sight (distances 0..cells_ahead-1). A vehicle marks every cell its footprint overlaps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from perception.types import WorldState


@dataclass(frozen=True)
class GridConfig:
    """Grid extent: cell length [m], cells ahead including the ego's (line of sight), cells behind."""

    cell_length: float = 5.0
    cells_ahead: int = 9
    cells_behind: int = 4

    def __post_init__(self) -> None:
        if not (math.isfinite(self.cell_length) and self.cell_length > 0):
            raise ValueError(f"grid cell_length must be > 0 m, got {self.cell_length}")
        if self.cells_ahead < 1 or self.cells_behind < 0:
            raise ValueError(
                f"grid needs cells_ahead >= 1 and cells_behind >= 0, "
                f"got {self.cells_ahead} and {self.cells_behind}"
            )

    @property
    def cells(self) -> int:
        return self.cells_behind + self.cells_ahead

    @property
    def ego_column(self) -> int:
        return self.cells_behind


def lane_code_bits(lanes: int) -> int:
    """Bits of the binary ego-lane code (the paper's encoding)."""
    return max(1, math.ceil(math.log2(lanes)))


@dataclass(frozen=True)
class OccupancyGrid:
    """Presence grid (lanes x cells, 0/1 float32) plus where the ego is."""

    cells: np.ndarray
    ego_lane: int
    config: GridConfig

    @property
    def lanes(self) -> int:
        return self.cells.shape[0]

    def distances_ahead(self) -> np.ndarray:
        """Per lane, cells from the ego's column to the closest occupied one ahead (0 = beside the
        ego), or cells_ahead - 1 when the line of sight is clear (the paper caps at 8)."""
        ahead = self.cells[:, self.config.ego_column :] > 0
        first = np.argmax(ahead, axis=1)
        return np.where(ahead.any(axis=1), first, self.config.cells_ahead - 1)

    def to_paper_state(self) -> np.ndarray:
        """Flattened grid followed by the ego lane as a binary code (most significant bit first)."""
        bits = lane_code_bits(self.lanes)
        code = [(self.ego_lane >> (bits - 1 - i)) & 1 for i in range(bits)]
        return np.concatenate([self.cells.ravel(), np.asarray(code, dtype=np.float32)])

    def to_tabular_state(self) -> np.ndarray:
        """[ego_lane, distance to the closest car ahead in each lane] (the paper's tabular state)."""
        return np.concatenate([[self.ego_lane], self.distances_ahead()]).astype(np.int64)


def paper_state_space(lanes: int, config: GridConfig) -> spaces.Box:
    return spaces.Box(0.0, 1.0, shape=(lanes * config.cells + lane_code_bits(lanes),), dtype=np.float32)


def tabular_state_space(lanes: int, config: GridConfig) -> spaces.Box:
    high = np.array([lanes - 1] + [config.cells_ahead - 1] * lanes)
    return spaces.Box(0, high, dtype=np.int64)


class OccupancyGridBuilder:
    """`build(world)`: the lane-aligned, ego-relative presence grid, vectorised over vehicles."""

    def __init__(self, config: GridConfig) -> None:
        self.config = config

    def build(self, world: WorldState) -> OccupancyGrid:
        config = self.config
        others = slice(1, None)
        states = np.stack([world.s[others], world.d[others], world.speed[others]])
        if not np.all(np.isfinite(states)):
            bad = int(np.nonzero(~np.all(np.isfinite(states), axis=0))[0][0]) + 1
            raise ValueError(f"vehicle id {int(world.ids[bad])} has a non-finite state")

        rel_s = world.s[others] - world.s[0]
        half_length = world.length[others] / 2
        first = np.floor((rel_s - half_length) / config.cell_length + 0.5).astype(int)
        last = np.ceil((rel_s + half_length) / config.cell_length + 0.5).astype(int) - 1
        columns = np.arange(config.cells) - config.ego_column
        along = (columns[None, :] >= first[:, None]) & (columns[None, :] <= last[:, None])

        half_width = world.width[others] / 2
        half_lane = world.lane_width / 2
        lane_low = world.lane_offsets - half_lane
        lane_high = world.lane_offsets + half_lane
        d = world.d[others]
        across = ((d - half_width)[:, None] < lane_high[None, :]) & (
            (d + half_width)[:, None] > lane_low[None, :]
        )

        cells = np.einsum("vl,vc->lc", across.astype(np.float32), along.astype(np.float32))
        return OccupancyGrid(cells=(cells > 0).astype(np.float32), ego_lane=int(world.lane[0]), config=config)
