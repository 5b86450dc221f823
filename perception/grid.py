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

One law, two paths: the grid of one world (presence, relative speed, TTC) is
`perception.grid_law.fill_grid`; `OccupancyGridBuilder.build` calls it compiled on its own world
and `observe_batch` on every world of a `WorldBatch`, each world's `observation` encoding written
in place, to the same bits.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from gymnasium import spaces

from perception import features
from perception.grid_law import (
    GridLaw,
    GridParts,
    GridWorld,
    GridWorlds,
    ObservationLayout,
    ego_speed_value,
    fill_grid_compiled,
    longitudinal_speed,
    observe_worlds,
    write_lane_part,
)
from records import (
    ENCODINGS,
    FEATURES,
    TRAFFIC_VALUES,
    Encoding,
    GridConfig,
    WorldState,
    unknown_name,
)
from records.batch import WorldBatch

BATCHED_FEATURES = tuple(name for name in FEATURES if name != "traffic")
"""The grid features `observe_batch` computes (in the observation's order)."""


def _observation_low(name: str, size: int) -> np.ndarray:
    """Lower bound of the observation part `name` (upper bounds are all 1)."""
    if name in ("relative_speed", "ego_lateral"):
        return -np.ones(size, dtype=np.float32)
    if name == "traffic":
        return np.tile(np.array([-1, -1, 0], dtype=np.float32), size // TRAFFIC_VALUES)
    return np.zeros(size, dtype=np.float32)


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
        part = np.zeros(self.config.lane_code_size(self.lanes_count), dtype=np.float32)
        write_lane_part(part, self.ego_lane, self.lanes_count, self.config.lane_code == "sides")
        return part

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
    """`build(world)`: the lane-aligned, ego-relative grid (`fill_grid`, compiled)."""

    def __init__(self, config: GridConfig) -> None:
        self.config = config
        self.law = GridLaw.of(config)
        self.with_speeds = bool({"relative_speed", "traffic"} & set(config.features))

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
        ego_lane, n = int(world.lane[0]), world.count
        speed = _floats(world.speed)
        if self.with_speeds:
            lane_heading = world.lanes[0].heading_at(float(world.s[0]))
            longitudinal = _floats(longitudinal_speed(speed, _floats(world.heading), lane_heading))
        else:
            longitudinal = np.zeros(n)
        rows = config.rows(world.lanes_count)
        parts = GridParts(
            np.zeros((rows, config.cells), dtype=np.float32),
            np.zeros((rows, config.cells), dtype=np.float32),
            np.empty(rows, dtype=np.float32),
            np.empty(rows, dtype=np.int64),
            np.zeros(n),
            np.empty((rows, n), dtype=np.bool_),
        )
        one = GridWorld(
            n,
            _floats(world.s),
            _floats(world.d),
            speed,
            longitudinal,
            _floats(world.length),
            _floats(world.width),
            _floats(world.lane_offsets),
            world.lanes_count,
            world.lane_width,
            ego_lane,
        )
        fill_grid_compiled(one, self.law, parts)
        features_on = config.features
        traffic = None
        if "traffic" in features_on:
            rel_s = world.s[1:] - world.s[0]
            traffic = features.traffic(world, parts.value[1:], rel_s, parts.in_row[:, 1:], parts.road)
        return OccupancyGrid(
            parts.presence,
            ego_lane,
            world.lanes_count,
            config,
            parts.relative_speed if "relative_speed" in features_on else None,
            parts.ttc if "ttc" in features_on else None,
            ego_speed_value(float(world.speed[0])) if "ego_speed" in features_on else None,
            features.ego_lateral(world) if "ego_lateral" in features_on else None,
            traffic,
        )


def _floats(values: np.ndarray) -> np.ndarray:
    """`values` as a contiguous float64 array (no copy when they are one): what `fill_grid` is
    compiled for."""
    return np.ascontiguousarray(values, dtype=np.float64)


def _reject_non_finite(world: WorldState) -> None:
    states = np.stack([world.s, world.d, world.speed, world.heading])
    finite = np.all(np.isfinite(states), axis=0)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        name = "the ego" if row == 0 else f"vehicle id {int(world.ids[row])}"
        raise ValueError(f"{name} has a non-finite state (s, d, speed or heading); refusing to grid it")


@lru_cache(maxsize=64)
def _batched_encoding(
    config: GridConfig, lanes_counts: frozenset[int]
) -> tuple[int, GridLaw, ObservationLayout]:
    """The values of one world's observation, the law and the layout of a batch of roads of
    `lanes_counts` lanes; ValueError (one line) for what the batch cannot encode: a feature not in
    `BATCHED_FEATURES`, or observations of different sizes (absolute rows or the binary lane code
    on roads of different lane counts)."""
    unbatched = [name for name in config.features if name not in BATCHED_FEATURES]
    if unbatched:
        raise ValueError(
            f"perception.features: the batched grid computes {', '.join(BATCHED_FEATURES)}, "
            f"not {unbatched[0]}"
        )
    sizes = {sum(size for _, size in config.observation_layout(lanes)) for lanes in lanes_counts}
    if len(sizes) != 1:
        raise ValueError(
            "perception: observations of one size on every road of a batch need lanes: ego and "
            "lane_code: sides"
        )
    return sizes.pop(), GridLaw.of(config), ObservationLayout.of(config, min(lanes_counts))


def observe_batch(config: GridConfig, batch: WorldBatch) -> np.ndarray:
    """(worlds, values) float32: each world's `observation` encoding of the grid `config`
    describes, `OccupancyGridBuilder.build(world).encode("observation")` of every world to the
    same bits."""
    size, law, layout = _batched_encoding(config, frozenset(batch.lanes_count.tolist()))
    states = np.stack([batch.s, batch.d, batch.speed, batch.heading])
    padding = np.arange(batch.s.shape[1])[None, :] >= batch.count[:, None]
    finite = (np.isfinite(states).all(axis=0) | padding).all(axis=1)
    if not finite.all():
        world = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"world {world} has a non-finite state (s, d, speed or heading); refusing to grid it"
        )
    longitudinal = longitudinal_speed(batch.speed, batch.heading, batch.lane_heading[:, None])
    observations = np.zeros((batch.worlds, size), dtype=np.float32)
    with_lateral = layout.ego_lateral >= 0
    lateral = _ego_lateral(batch) if with_lateral else np.zeros((batch.worlds, 2), dtype=np.float32)
    worlds = GridWorlds(
        batch.count,
        batch.s,
        batch.d,
        batch.speed,
        longitudinal,
        batch.length,
        batch.width,
        batch.lane_offsets,
        batch.lanes_count,
        batch.lane_width,
        np.ascontiguousarray(batch.lane[:, 0]),
    )
    observe_worlds(observations, worlds, law, layout, lateral)
    return observations


def _ego_lateral(batch: WorldBatch) -> np.ndarray:
    """(worlds, 2) float32: each world's `features.ego_lateral`. A batch's lanes are parallel
    straight lanes of one segment, so the ego's lane has lane 0's heading."""
    lateral = np.empty((batch.worlds, 2), dtype=np.float32)
    for w in range(batch.worlds):
        centre = batch.lane_offsets[w, int(batch.lane[w, 0])]
        lateral[w] = features.lateral_feature(
            batch.d[w, 0], centre, batch.lane_width, batch.heading[w, 0], batch.lane_heading[w]
        )
    return lateral
