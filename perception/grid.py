"""Occupancy grid of the ego's surroundings and the paper's encodings.

Rows are lanes, columns are longitudinal cells of `cell_length` metres, ego-relative in x: column
`cells_behind` is the ego's own cell ([-L/2, L/2) around the ego's centre), the `cells_ahead`
columns from there on are the paper's line of sight (distances 0..cells_ahead-1). Coordinates are
lane-frame (s along the reference lane, d across it), so the grid follows curved roads.

Rows: `lanes="absolute"` gives one row per road lane (row = lane index, as the paper);
`lanes="ego"` gives 2 * lateral_reach + 1 rows centred on the ego's lane (row 0 = the leftmost
neighbour considered), lanes that do not exist marked occupied, so an agent trained on one lane
count works on another. A vehicle marks every cell its footprint (length x width) overlaps, in
every lane it overlaps (`footprint=False`: only the cell of its centre, as highway-env's own
`OccupancyGrid` observation).

Optional features (`features`):
- `relative_speed`: per cell, the longitudinal speed (along the lane heading at the ego) of the
  nearest occupant minus the ego's, divided by `speed_scale` [m/s], clipped to [-1, 1]; 0 if empty;
- `ttc`: per row, time-to-collision [s] with the nearest vehicle ahead that the ego closes on,
  min(ttc, ttc_horizon) / ttc_horizon in [0, 1]: 1 = no threat within the horizon;
- `ego_speed`: one value, the ego's speed / MAX_SPEED in [0, 1];
- `ego_lateral`: two values, the ego's offset from its lane's centre / lane width in [-1, 1] and
  its heading relative to the lane / EGO_HEADING_SCALE clipped to [-1, 1]: a lane change under way
  shows in both (positive towards the higher lane indices, the right);
- `traffic`: per row, the vehicles within TRAFFIC_RANGE [m] ahead of the ego in that lane, beyond the
  grid's sight: their mean and lowest relative speed (as `relative_speed`; 0 when there are none) and
  the share of the range their lengths fill, in [0, 1]; [0, 0, 1] off the road.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from perception import features
from records import (
    ENCODINGS,
    FEATURES,
    MAX_SPEED,
    SIDE_LANES_SEEN,
    TRAFFIC_VALUES,
    Encoding,
    GridConfig,
    WorldState,
    lane_code_bits,
    unknown_name,
)


def _observation_low(name: str, size: int) -> np.ndarray:
    """Lower bound of the observation part `name` (upper bounds are all 1)."""
    if name in ("relative_speed", "ego_lateral"):
        return -np.ones(size, dtype=np.float32)
    if name == "traffic":
        return np.tile(np.array([-1, -1, 0], dtype=np.float32), size // TRAFFIC_VALUES)
    return np.zeros(size, dtype=np.float32)


def lane_code(lane: int, lanes: int) -> np.ndarray:
    """`lane` as a binary code, most significant bit first."""
    bits = lane_code_bits(lanes)
    return np.array([(lane >> (bits - 1 - i)) & 1 for i in range(bits)], dtype=np.float32)


def side_lanes_code(lane: int, lanes: int) -> np.ndarray:
    """[lanes left of `lane`, lanes right of it], each capped at SIDE_LANES_SEEN and scaled to [0, 1]."""
    sides = np.array([lane, lanes - 1 - lane], dtype=np.float32)
    return np.minimum(sides, SIDE_LANES_SEEN) / SIDE_LANES_SEEN


@dataclass(frozen=True)
class OccupancyGrid:
    """Presence (rows x cells, 0/1), optional features, and where the ego is."""

    cells: np.ndarray
    ego_lane: int
    lanes_count: int
    config: GridConfig
    relative_speed: np.ndarray | None = None
    ttc: np.ndarray | None = None
    ego_speed: float | None = None
    ego_lateral: np.ndarray | None = None
    traffic: np.ndarray | None = None

    @property
    def ego_row(self) -> int:
        return self.ego_lane if self.config.lanes == "absolute" else self.config.lateral_reach

    def row_lane(self, row: int) -> int:
        """Road lane index of grid row `row` (may be off the road in ego mode)."""
        return row if self.config.lanes == "absolute" else self.ego_lane - self.config.lateral_reach + row

    def distances_ahead(self, line_of_sight: int | None = None) -> np.ndarray:
        """Per row, cells from the ego's column to the closest occupied one ahead (0 = beside the
        ego), or line_of_sight - 1 when nothing is in sight (the paper caps at 8)."""
        line_of_sight = min(line_of_sight or self.config.cells_ahead, self.config.cells_ahead)
        ahead = self.cells[:, self.config.ego_column : self.config.ego_column + line_of_sight] > 0
        return np.where(ahead.any(axis=1), np.argmax(ahead, axis=1), line_of_sight - 1)

    def lane_part(self) -> np.ndarray:
        """Where the ego is, as `config.lane_code` says: its lane in binary, or its side lanes."""
        if self.config.lane_code == "sides":
            return side_lanes_code(self.ego_lane, self.lanes_count)
        return lane_code(self.ego_lane, self.lanes_count)

    def to_paper_state(self) -> np.ndarray:
        """Flattened presence grid followed by the ego lane as a binary code (the paper's DQN state)."""
        return np.concatenate([self.cells.ravel(), self.lane_part()])

    def to_observation(self) -> np.ndarray:
        """Presence, then each enabled feature, then the lane part, flattened (float32): the parts of
        `GridConfig.observation_layout`."""
        parts = [np.ravel(getattr(self, name)) for name in FEATURES if getattr(self, name) is not None]
        return np.concatenate([self.cells.ravel(), *parts, self.lane_part()]).astype(np.float32)

    def encode(self, encoding: Encoding) -> np.ndarray:
        """The encoding named `encoding`: paper, observation or tabular."""
        if encoding == "paper":
            return self.to_paper_state()
        if encoding == "observation":
            return self.to_observation()
        if encoding == "tabular":
            return self.to_tabular_state()
        raise ValueError(unknown_name("encoding", encoding, ENCODINGS))

    def to_tabular_state(self, line_of_sight: int | None = None) -> np.ndarray:
        """[where the ego is, distance in cells to the closest car ahead in each row] (the paper's
        tabular state), capped at line_of_sight - 1. Where the ego is: its lane index, or with
        the `sides` lane code 2 x (a lane on its left) + (a lane on its right), 0-3 on any road."""
        where = self.ego_lane
        if self.config.lane_code == "sides":
            where = 2 * min(self.ego_lane, 1) + min(self.lanes_count - 1 - self.ego_lane, 1)
        return np.concatenate([[where], self.distances_ahead(line_of_sight)]).astype(np.int64)


class OccupancyGridBuilder:
    """`build(world)`: the lane-aligned, ego-relative grid, vectorised over vehicles."""

    def __init__(self, config: GridConfig) -> None:
        self.config = config

    def paper_space(self, lanes_count: int) -> spaces.Box:
        size = self.config.rows(lanes_count) * self.config.cells + self.config.lane_code_size(lanes_count)
        return spaces.Box(0.0, 1.0, shape=(size,), dtype=np.float32)

    def observation_space(self, lanes_count: int) -> spaces.Box:
        layout = self.config.observation_layout(lanes_count)
        low = np.concatenate([_observation_low(name, size) for name, size in layout])
        return spaces.Box(low, np.ones_like(low), dtype=np.float32)

    def tabular_space(self, lanes_count: int) -> spaces.Box:
        where = 3 if self.config.lane_code == "sides" else lanes_count - 1
        high = np.array([where] + [self.config.cells_ahead - 1] * self.config.rows(lanes_count))
        return spaces.Box(0, high, dtype=np.int64)

    def space(self, encoding: Encoding, lanes_count: int) -> spaces.Box:
        """The observation space of `encoding` on a road of `lanes_count` lanes."""
        return {
            "paper": self.paper_space,
            "observation": self.observation_space,
            "tabular": self.tabular_space,
        }[encoding](lanes_count)

    def build(self, world: WorldState) -> OccupancyGrid:
        config = self.config
        _reject_non_finite(world)
        ego_lane = int(world.lane[0])
        rel_s = world.s[1:] - world.s[0]
        along = self._columns(rel_s, world.length[1:])
        across = self._lanes(world)
        rows = config.rows(world.lanes_count)
        road_rows = self._road_rows(ego_lane, world.lanes_count)
        occupancy = np.zeros((rows, config.cells), dtype=np.float32)
        on_road = road_rows >= 0
        occupancy[on_road] = (
            across[:, road_rows[on_road]].T.astype(np.float32) @ along.astype(np.float32)
        ) > 0
        occupancy[~on_road] = 1.0
        relative_speed = ttc = traffic = None
        if {"relative_speed", "traffic"} & set(config.features):
            value = features.relative_longitudinal_speed(config, world)
        if "relative_speed" in config.features:
            relative_speed = features.relative_speed(config, value, rel_s, along, across, road_rows)
        if "ttc" in config.features:
            ttc = features.time_to_collision(config, world, rel_s, across, road_rows)
        ego_speed = (
            float(np.clip(world.speed[0] / MAX_SPEED, 0, 1)) if "ego_speed" in config.features else None
        )
        ego_lateral = features.ego_lateral(world) if "ego_lateral" in config.features else None
        if "traffic" in config.features:
            traffic = features.traffic(world, value, rel_s, across, road_rows)
        return OccupancyGrid(
            occupancy,
            ego_lane,
            world.lanes_count,
            config,
            relative_speed,
            ttc,
            ego_speed,
            ego_lateral,
            traffic,
        )

    def _road_rows(self, ego_lane: int, lanes_count: int) -> np.ndarray:
        """Road lane index of each grid row, -1 where the lane does not exist."""
        if self.config.lanes == "absolute":
            return np.arange(lanes_count)
        lanes = ego_lane + np.arange(-self.config.lateral_reach, self.config.lateral_reach + 1)
        return np.where((lanes >= 0) & (lanes < lanes_count), lanes, -1)

    def _columns(self, rel_s: np.ndarray, length: np.ndarray) -> np.ndarray:
        """(vehicles, cells) mask of the columns each vehicle covers."""
        config = self.config
        offsets = np.arange(config.cells) - config.ego_column
        if config.footprint:
            first = np.floor((rel_s - length / 2) / config.cell_length + 0.5)
            last = np.ceil((rel_s + length / 2) / config.cell_length + 0.5) - 1
        else:
            first = last = np.floor(rel_s / config.cell_length + 0.5)
        return (offsets[None, :] >= first[:, None]) & (offsets[None, :] <= last[:, None])

    def _lanes(self, world: WorldState) -> np.ndarray:
        """(vehicles, road lanes) mask of the lanes each vehicle covers."""
        d = world.d[1:]
        half_lane = world.lane_width / 2
        if not self.config.footprint:
            return np.abs(d[:, None] - world.lane_offsets[None, :]) < half_lane
        half_width = world.width[1:, None] / 2
        low, high = world.lane_offsets - half_lane, world.lane_offsets + half_lane
        return (d[:, None] - half_width < high[None, :]) & (d[:, None] + half_width > low[None, :])


def _reject_non_finite(world: WorldState) -> None:
    states = np.stack([world.s, world.d, world.speed, world.heading])
    finite = np.all(np.isfinite(states), axis=0)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        name = "the ego" if row == 0 else f"vehicle id {int(world.ids[row])}"
        raise ValueError(f"{name} has a non-finite state (s, d, speed or heading); refusing to grid it")
