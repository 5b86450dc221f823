"""The `observation` encoding of many worlds at once: `OccupancyGridBuilder.build(world).encode(
"observation")` for every world of a `WorldBatch`, in one compiled pass, to the same bits.

Each world's presence grid, its `relative_speed` and `ttc` features, the ego's speed and its lane
part follow `perception.grid` and `perception.features` operation by operation (sums, products,
divisions, floor and ceil give numpy's bits in numba); the one transcendental call, the cosine of
each vehicle's heading to the lane, runs in numpy over the whole batch, as the per-world code runs
it over one world. Where two vehicles at exactly the same distance from the ego cover one cell, the
per-world code keeps the one numpy's sort puts last and this kernel the one with the higher row; no
simulated world has shown such a tie. `ego_lateral` runs per world in numpy, as `perception.features`
runs it (its sine, cosine and arctangent on one world's scalars); the `traffic` feature is not batched.
"""

from __future__ import annotations

import math

import numpy as np

from common.compiled import Kernel
from perception.features import lateral_feature
from records import FEATURES, MAX_SPEED, SIDE_LANES_SEEN, GridConfig
from records.batch import WorldBatch

BATCHED_FEATURES = tuple(name for name in FEATURES if name != "traffic")
"""The grid features the batched encoding computes (in the observation's order)."""


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
    """(worlds, values) float32: each world's `observation` encoding of the grid `config` describes."""
    size = batched_size(config, batch)
    states = np.stack([batch.s, batch.d, batch.speed, batch.heading])
    padding = np.arange(batch.s.shape[1])[None, :] >= batch.count[:, None]
    finite = (np.isfinite(states).all(axis=0) | padding).all(axis=1)
    if not finite.all():
        world = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"world {world} has a non-finite state (s, d, speed or heading); refusing to grid it"
        )
    longitudinal = batch.speed * np.cos(batch.heading - batch.lane_heading[:, None])
    observations = np.zeros((batch.worlds, size), dtype=np.float32)
    with_lateral = "ego_lateral" in config.features
    lateral = ego_lateral(batch) if with_lateral else np.zeros((batch.worlds, 2), dtype=np.float32)
    _observe(
        observations,
        batch.columns(),
        batch.lane_width,
        longitudinal,
        config.cell_length,
        config.cells_behind,
        config.cells,
        config.lanes == "ego",
        config.lateral_reach,
        config.footprint,
        "relative_speed" in config.features,
        "ttc" in config.features,
        "ego_speed" in config.features,
        with_lateral,
        lateral,
        config.speed_scale,
        config.ttc_horizon,
        config.lane_code == "sides",
        MAX_SPEED,
        SIDE_LANES_SEEN,
    )
    return observations


def ego_lateral(batch: WorldBatch) -> np.ndarray:
    """(worlds, 2) float32: each world's `features.ego_lateral`, the ego's offset from its lane's
    centre / lane width and its heading error / EGO_HEADING_SCALE, in [-1, 1]. A batch's lanes are
    parallel straight lanes of one segment, so the ego's lane has lane 0's heading."""
    lateral = np.empty((batch.worlds, 2), dtype=np.float32)
    for w in range(batch.worlds):
        centre = batch.lane_offsets[w, int(batch.lane[w, 0])]
        lateral[w] = lateral_feature(
            batch.d[w, 0], centre, batch.lane_width, batch.heading[w, 0], batch.lane_heading[w]
        )
    return lateral


@Kernel
def _observe(
    out: np.ndarray,
    columns: tuple[np.ndarray, ...],
    lane_width: float,
    longitudinal: np.ndarray,
    cell_length: float,
    ego_column: int,
    cells: int,
    ego_rows: bool,
    reach: int,
    footprint: bool,
    with_relative_speed: bool,
    with_ttc: bool,
    with_ego_speed: bool,
    with_ego_lateral: bool,
    ego_lateral: np.ndarray,
    speed_scale: float,
    ttc_horizon: float,
    sides: bool,
    max_speed: float,
    side_lanes_seen: int,
) -> None:  # pragma: no cover - compiled; covered through observe_batch
    count, s, d, speed, length, width, lane, lanes_count, lane_offsets = columns
    half_lane = lane_width / 2
    for w in range(out.shape[0]):
        n, lanes, ego_lane = count[w], lanes_count[w], lane[w, 0]
        rows = 2 * reach + 1 if ego_rows else lanes
        first = np.empty(n)
        last = np.empty(n)
        for v in range(1, n):
            rel = s[w, v] - s[w, 0]
            if footprint:
                first[v] = math.floor((rel - length[w, v] / 2) / cell_length + 0.5)
                last[v] = math.ceil((rel + length[w, v] / 2) / cell_length + 0.5) - 1
            else:
                first[v] = last[v] = math.floor(rel / cell_length + 0.5)
        road = np.empty(rows, dtype=np.int64)
        for row in range(rows):
            road[row] = row if not ego_rows else ego_lane - reach + row
            if road[row] < 0 or road[row] >= lanes:
                road[row] = -1
        cursor = rows * cells
        relative_at = cursor
        if with_relative_speed:
            cursor += rows * cells
        ttc_at = cursor
        if with_ttc:
            cursor += rows
        nearest = np.full((rows, cells), np.inf)
        closest_ahead = np.full(rows, np.inf)
        closest_row = np.full(rows, -1, dtype=np.int64)
        for row in range(rows):
            if road[row] < 0:
                for column in range(cells):
                    out[w, row * cells + column] = 1.0
                continue
            centre = lane_offsets[w, road[row]]
            for v in range(1, n):
                if footprint:
                    half_width = width[w, v] / 2
                    inside = (
                        d[w, v] - half_width < centre + half_lane
                        and d[w, v] + half_width > centre - half_lane
                    )
                else:
                    inside = abs(d[w, v] - centre) < half_lane
                if not inside:
                    continue
                rel = s[w, v] - s[w, 0]
                if rel > 0 and rel < closest_ahead[row]:
                    closest_ahead[row], closest_row[row] = rel, v
                distance = abs(rel)
                value = (longitudinal[w, v] - longitudinal[w, 0]) / speed_scale
                value = min(max(value, -1.0), 1.0)
                for column in range(cells):
                    offset = column - ego_column
                    if offset < first[v] or offset > last[v]:
                        continue
                    out[w, row * cells + column] = 1.0
                    if with_relative_speed and distance <= nearest[row, column]:
                        nearest[row, column] = distance
                        out[w, relative_at + row * cells + column] = value
        if with_ttc:
            for row in range(rows):
                if road[row] < 0:
                    out[w, ttc_at + row] = 0.0
                    continue
                out[w, ttc_at + row] = 1.0
                v = closest_row[row]
                if v < 0:
                    continue
                closing = speed[w, 0] - speed[w, v]
                if closing > 0:
                    gap = (s[w, v] - s[w, 0]) - (length[w, v] + length[w, 0]) / 2
                    seconds = max(gap, 0.0) / closing
                    out[w, ttc_at + row] = min(seconds, ttc_horizon) / ttc_horizon
        if with_ego_speed:
            out[w, cursor] = min(max(speed[w, 0] / max_speed, 0.0), 1.0)
            cursor += 1
        if with_ego_lateral:
            out[w, cursor] = ego_lateral[w, 0]
            out[w, cursor + 1] = ego_lateral[w, 1]
            cursor += 2
        if sides:
            out[w, cursor] = min(ego_lane, side_lanes_seen) / side_lanes_seen
            out[w, cursor + 1] = min(lanes - 1 - ego_lane, side_lanes_seen) / side_lanes_seen
        else:
            bits = out.shape[1] - cursor
            for bit in range(bits):
                out[w, cursor + bit] = (ego_lane >> (bits - 1 - bit)) & 1
