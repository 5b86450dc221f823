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

One law, two paths: `fill_grid` is the grid of one world (presence, relative speed, TTC), a plain
function that numba compiles; `OccupancyGridBuilder.build` calls it on its own world and
`observe_batch` loops over the worlds of a `WorldBatch` around it, writing each world's `observation`
encoding in place, to the same bits. Where two vehicles at exactly the same distance from the ego
cover one cell, the one with the higher row gives its relative speed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from gymnasium import spaces
from numba import njit

from common import neighbours
from common.compiled import Kernel
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
    unknown_name,
)
from records.batch import WorldBatch

BATCHED_FEATURES = tuple(name for name in FEATURES if name != "traffic")
"""The grid features `observe_batch` computes (in the observation's order)."""


class GridLaw(NamedTuple):
    """A `GridConfig` as `fill_grid` reads it: cells of `cell_length` [m], the ego's in column
    `ego_column` of `cells`; rows centred on the ego's lane (`ego_rows`, `reach` lanes each side)
    or one per road lane; `footprint`: a vehicle fills every cell and lane its footprint overlaps,
    else the cell and lane of its centre; relative speeds scaled by `speed_scale` [m/s], times to
    collision by `ttc_horizon` [s]."""

    cell_length: float
    ego_column: int
    cells: int
    ego_rows: bool
    reach: int
    footprint: bool
    speed_scale: float
    ttc_horizon: float

    @classmethod
    def of(cls, config: GridConfig) -> GridLaw:
        return cls(
            float(config.cell_length),
            config.ego_column,
            config.cells,
            config.lanes == "ego",
            config.lateral_reach,
            config.footprint,
            float(config.speed_scale),
            float(config.ttc_horizon),
        )


class GridWorld(NamedTuple):
    """One world as `fill_grid` reads it: `vehicles` rows (row 0 the ego) at `s`, `d` [m] in the
    reference lane's frame, their `speed` [m/s], `longitudinal` speed along the lane at the ego
    (`longitudinal_speed`) [m/s], `length` and `width` [m]; lane k's centre at `lane_offsets[k]`
    of `lanes_count` lanes `lane_width` [m] wide; the ego in lane `ego_lane`."""

    vehicles: int
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    longitudinal: np.ndarray
    length: np.ndarray
    width: np.ndarray
    lane_offsets: np.ndarray
    lanes_count: int
    lane_width: float
    ego_lane: int


class GridParts(NamedTuple):
    """What `fill_grid` writes of one world of `rows` grid rows and `vehicles` rows: `presence` and
    `relative_speed` (rows, cells) float32 (zeros on entry), `ttc` (rows,) float32, `road` (rows,)
    the road lane of each row (-1 off the road), `value` (vehicles,) each vehicle's relative speed
    (`relative_speed`'s value, clipped to [-1, 1]) and `in_row` (rows, vehicles) the rows each
    vehicle covers (the ego's column unused)."""

    presence: np.ndarray
    relative_speed: np.ndarray
    ttc: np.ndarray
    road: np.ndarray
    value: np.ndarray
    in_row: np.ndarray


def longitudinal_speed(
    speed: np.ndarray, heading: np.ndarray, lane_heading: np.ndarray | float
) -> np.ndarray:
    """Each vehicle's `speed` [m/s] along the lane heading at the ego `lane_heading` [rad], in
    numpy over one world or a batch (numpy's cosine: one element's bits on any array)."""
    return np.asarray(speed * np.cos(heading - lane_heading))


def ego_speed_value(speed: float) -> float:
    """The `ego_speed` feature of an ego at `speed` [m/s]: speed / MAX_SPEED in [0, 1]."""
    return min(max(speed / MAX_SPEED, 0.0), 1.0)


def write_lane_part(out: np.ndarray, lane: int, lanes: int, sides: bool) -> None:
    """The lane part of the encodings into `out`: with `sides`, [lanes left of `lane`, lanes right
    of it] each capped at SIDE_LANES_SEEN and scaled to [0, 1]; else `lane` as a binary code of
    len(out) bits, most significant first."""
    if sides:
        out[0] = min(lane, SIDE_LANES_SEEN) / SIDE_LANES_SEEN
        out[1] = min(lanes - 1 - lane, SIDE_LANES_SEEN) / SIDE_LANES_SEEN
        return
    bits = len(out)
    for bit in range(bits):
        out[bit] = (lane >> (bits - 1 - bit)) & 1


_reaches_lane = njit(cache=True, nogil=True, inline="always")(neighbours.reaches_lane)
_ego_speed_value = njit(cache=True, nogil=True, inline="always")(ego_speed_value)
_write_lane_part = njit(cache=True, nogil=True)(write_lane_part)


def fill_grid(world: GridWorld, law: GridLaw, parts: GridParts) -> None:
    """The grid of one world into `parts`: each row's road lane; each other vehicle's columns
    (ego-relative, cells of `cell_length`) and rows, marked present; per cell the relative speed
    of its nearest occupant; per row min(TTC with the nearest vehicle ahead the ego closes on,
    horizon) / horizon, 1 with none, 0 off the road. Compiled for both paths (`_fill_grid`)."""
    n, half_lane = world.vehicles, world.lane_width / 2
    rows, cells = parts.presence.shape
    for row in range(rows):
        lane = world.ego_lane - law.reach + row if law.ego_rows else row
        parts.road[row] = lane if 0 <= lane < world.lanes_count else -1
    first = np.empty(n)
    last = np.empty(n)
    for v in range(1, n):
        rel = world.s[v] - world.s[0]
        if law.footprint:
            first[v] = np.floor((rel - world.length[v] / 2) / law.cell_length + 0.5)
            last[v] = np.ceil((rel + world.length[v] / 2) / law.cell_length + 0.5) - 1
        else:
            first[v] = last[v] = np.floor(rel / law.cell_length + 0.5)
        value = (world.longitudinal[v] - world.longitudinal[0]) / law.speed_scale
        parts.value[v] = min(max(value, -1.0), 1.0)
    nearest = np.full((rows, cells), np.inf)
    for row in range(rows):
        parts.ttc[row] = 0.0
        for v in range(n):
            parts.in_row[row, v] = False
        lane = parts.road[row]
        if lane < 0:
            parts.presence[row] = 1.0
            continue
        parts.ttc[row] = 1.0
        centre = world.lane_offsets[lane]
        closest, closest_at = np.inf, -1
        for v in range(1, n):
            if law.footprint:
                half_width = world.width[v] / 2
                inside = _reaches_lane(
                    world.d[v] - half_width, world.d[v] + half_width, centre, world.lane_width
                )
            else:
                inside = abs(world.d[v] - centre) < half_lane
            if not inside:
                continue
            parts.in_row[row, v] = True
            rel = world.s[v] - world.s[0]
            if 0 < rel < closest:
                closest, closest_at = rel, v
            for column in range(cells):
                offset = column - law.ego_column
                if offset < first[v] or offset > last[v]:
                    continue
                parts.presence[row, column] = 1.0
                if abs(rel) <= nearest[row, column]:
                    nearest[row, column] = abs(rel)
                    parts.relative_speed[row, column] = parts.value[v]
        if closest_at > 0:
            closing = world.speed[0] - world.speed[closest_at]
            if closing > 0:
                gap = closest - (world.length[closest_at] + world.length[0]) / 2
                seconds = max(gap, 0.0) / closing
                parts.ttc[row] = min(seconds, law.ttc_horizon) / law.ttc_horizon


_fill_grid = Kernel(fill_grid)
_fill_grid_compiled = _fill_grid.compiled


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
        _fill_grid(one, self.law, parts)
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


class ObservationLayout(NamedTuple):
    """Where each part of the `observation` encoding starts in a world's row (-1: not encoded):
    `GridConfig.observation_layout` as `_observe` reads it."""

    presence: int
    relative_speed: int
    ttc: int
    ego_speed: int
    ego_lateral: int
    lane: int
    sides: bool

    @classmethod
    def of(cls, config: GridConfig, lanes_count: int) -> ObservationLayout:
        starts, at = {}, 0
        for name, size in config.observation_layout(lanes_count):
            starts[name] = at
            at += size
        return cls(
            presence=starts["presence"],
            relative_speed=starts.get("relative_speed", -1),
            ttc=starts.get("ttc", -1),
            ego_speed=starts.get("ego_speed", -1),
            ego_lateral=starts.get("ego_lateral", -1),
            lane=starts["lane"],
            sides=config.lane_code == "sides",
        )


def batched_size(config: GridConfig, batch: WorldBatch) -> int:
    """Values of one world's observation; ValueError (one line) for what the batch cannot encode:
    a feature not in `BATCHED_FEATURES`, or observations of different sizes (absolute rows or the
    binary lane code on roads of different lane counts)."""
    unbatched = [name for name in config.features if name not in BATCHED_FEATURES]
    if unbatched:
        raise ValueError(
            f"perception.features: the batched grid computes {', '.join(BATCHED_FEATURES)}, "
            f"not {unbatched[0]}"
        )
    sizes = {
        sum(size for _, size in config.observation_layout(int(lanes)))
        for lanes in set(batch.lanes_count.tolist())
    }
    if len(sizes) != 1:
        raise ValueError(
            "perception: observations of one size on every road of a batch need lanes: ego and "
            "lane_code: sides"
        )
    return sizes.pop()


def observe_batch(config: GridConfig, batch: WorldBatch) -> np.ndarray:
    """(worlds, values) float32: each world's `observation` encoding of the grid `config`
    describes, `OccupancyGridBuilder.build(world).encode("observation")` of every world to the
    same bits."""
    size = batched_size(config, batch)
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
    layout = ObservationLayout.of(config, int(batch.lanes_count[0]))
    with_lateral = layout.ego_lateral >= 0
    lateral = _ego_lateral(batch) if with_lateral else np.zeros((batch.worlds, 2), dtype=np.float32)
    _observe(observations, batch, longitudinal, GridLaw.of(config), layout, lateral)
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


def _observe(
    out: np.ndarray,
    batch: WorldBatch,
    longitudinal: np.ndarray,
    law: GridLaw,
    layout: ObservationLayout,
    lateral: np.ndarray,
) -> None:
    """`out[w]`: world w's observation (`_observe_worlds`)."""
    count, s, d, speed, length, width, lane, lanes_count, lane_offsets = batch.columns()
    _observe_worlds(
        out, count, s, d, speed, longitudinal, length, width, lane, lanes_count, lane_offsets,
        batch.lane_width, law, layout, lateral,
    )  # fmt: skip


@Kernel
def _observe_worlds(
    out: np.ndarray,
    count: np.ndarray,
    s: np.ndarray,
    d: np.ndarray,
    speed: np.ndarray,
    longitudinal: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    lane: np.ndarray,
    lanes_count: np.ndarray,
    lane_offsets: np.ndarray,
    lane_width: float,
    law: GridLaw,
    layout: ObservationLayout,
    lateral: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through observe_batch
    """Each world's `fill_grid` written into its row of `out` where `layout` puts each part, then
    the ego's speed and lateral state (`lateral`) and the lane part."""
    vehicles = s.shape[1]
    for w in range(out.shape[0]):
        row, lanes, ego_lane = out[w], lanes_count[w], lane[w, 0]
        rows = 2 * law.reach + 1 if law.ego_rows else lanes
        grid = rows * law.cells
        presence = row[layout.presence : layout.presence + grid].reshape((rows, law.cells))
        if layout.relative_speed >= 0:
            relative = row[layout.relative_speed : layout.relative_speed + grid].reshape((rows, law.cells))
        else:
            relative = np.zeros((rows, law.cells), dtype=np.float32)
        ttc = row[layout.ttc : layout.ttc + rows] if layout.ttc >= 0 else np.empty(rows, dtype=np.float32)
        parts = GridParts(
            presence,
            relative,
            ttc,
            np.empty(rows, dtype=np.int64),
            np.zeros(vehicles),
            np.empty((rows, vehicles), dtype=np.bool_),
        )
        world = GridWorld(
            count[w], s[w], d[w], speed[w], longitudinal[w], length[w], width[w], lane_offsets[w],
            lanes, lane_width, ego_lane,
        )  # fmt: skip
        _fill_grid_compiled(world, law, parts)
        if layout.ego_speed >= 0:
            row[layout.ego_speed] = _ego_speed_value(speed[w, 0])
        if layout.ego_lateral >= 0:
            row[layout.ego_lateral] = lateral[w, 0]
            row[layout.ego_lateral + 1] = lateral[w, 1]
        _write_lane_part(row[layout.lane :], ego_lane, lanes, layout.sides)
