"""The grid's per-tick law, written once: `fill_grid`, one world's presence grid, relative speeds
and times to collision, a plain function numba compiles. `OccupancyGridBuilder.build`
(`perception.grid`) calls it compiled on its own world; `observe_worlds` loops over the worlds of a
batch around the same function, writing each world's `observation` encoding in place. Sums,
products, divisions, floor and ceil give numpy's bits in numba; the one transcendental call, the
cosine of each vehicle's heading to the lane (`longitudinal_speed`), runs in numpy in both paths.
Where two vehicles at exactly the same distance from the ego cover one cell, the one with the
higher row gives its relative speed."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from common import neighbours
from common.compiled import Kernel
from records import MAX_SPEED, SIDE_LANES_SEEN, GridConfig


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
    vehicle covers (column 0, the ego's, unused)."""

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
    horizon) / horizon, 1 with none, 0 off the road."""
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
            start = min(max(first[v] + law.ego_column, 0.0), cells)
            stop = min(max(last[v] + law.ego_column + 1, 0.0), cells)
            for column in range(int(start), int(stop)):
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


fill_grid_compiled = Kernel(fill_grid)
"""`fill_grid` compiled: what the per-world builder calls (`Kernel`: a stop interrupts it)."""
_fill_grid = njit(cache=True, nogil=True, inline="always")(fill_grid)
"""`fill_grid` compiled into `observe_worlds` (inlined: the batch's loop pays no call per world)."""


class ObservationLayout(NamedTuple):
    """Where each part of the `observation` encoding starts in a world's row (-1: not encoded):
    `GridConfig.observation_layout` as `observe_worlds` reads it."""

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


class GridWorlds(NamedTuple):
    """Many worlds as `observe_worlds` reads them: `GridWorld`'s fields with a first axis of
    worlds (`vehicles`, `lanes_count` and `ego_lane` one value a world; one `lane_width`)."""

    vehicles: np.ndarray
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    longitudinal: np.ndarray
    length: np.ndarray
    width: np.ndarray
    lane_offsets: np.ndarray
    lanes_count: np.ndarray
    lane_width: float
    ego_lane: np.ndarray


@Kernel
def observe_worlds(
    out: np.ndarray, worlds: GridWorlds, law: GridLaw, layout: ObservationLayout, lateral: np.ndarray
) -> None:  # pragma: no cover - compiled; covered through perception.grid.observe_batch
    """Each world's `fill_grid` written into its row of `out` where `layout` puts each part, then
    the ego's speed and lateral state (`lateral`) and the lane part."""
    vehicles, cells = worlds.s.shape[1], law.cells
    rows_most = 2 * law.reach + 1 if law.ego_rows else max(worlds.lanes_count)
    road = np.empty(rows_most, dtype=np.int64)
    value = np.zeros(vehicles)
    in_row = np.empty(rows_most * vehicles, dtype=np.bool_)
    spare_relative = np.empty(rows_most * cells, dtype=np.float32)
    spare_ttc = np.empty(rows_most, dtype=np.float32)
    for w in range(out.shape[0]):
        row, lanes, ego_lane = out[w], worlds.lanes_count[w], worlds.ego_lane[w]
        rows = 2 * law.reach + 1 if law.ego_rows else lanes
        grid = rows * cells
        presence = row[layout.presence : layout.presence + grid].reshape((rows, cells))
        if layout.relative_speed >= 0:
            relative = row[layout.relative_speed : layout.relative_speed + grid].reshape((rows, cells))
        else:
            relative = spare_relative[:grid].reshape((rows, cells))
        ttc = row[layout.ttc : layout.ttc + rows] if layout.ttc >= 0 else spare_ttc[:rows]
        parts = GridParts(
            presence, relative, ttc, road[:rows], value, in_row[: rows * vehicles].reshape((rows, vehicles))
        )
        world = GridWorld(
            worlds.vehicles[w],
            worlds.s[w],
            worlds.d[w],
            worlds.speed[w],
            worlds.longitudinal[w],
            worlds.length[w],
            worlds.width[w],
            worlds.lane_offsets[w],
            lanes,
            worlds.lane_width,
            ego_lane,
        )
        _fill_grid(world, law, parts)
        if layout.ego_speed >= 0:
            row[layout.ego_speed] = _ego_speed_value(worlds.speed[w, 0])
        if layout.ego_lateral >= 0:
            row[layout.ego_lateral] = lateral[w, 0]
            row[layout.ego_lateral + 1] = lateral[w, 1]
        _write_lane_part(row[layout.lane :], ego_lane, lanes, layout.sides)
