"""The grid's optional features (`GridConfig.features`) computed in numpy, one world at a time: the
ego's lateral state (for the batch too, world by world) and the per-row traffic ahead (the per-world
grid only), from the rows `perception.grid.fill_grid` finds; `fill_grid` computes the relative speed
and time to collision."""

from __future__ import annotations

import numpy as np

from records import EGO_HEADING_SCALE, TRAFFIC_VALUES, WorldState

TRAFFIC_RANGE = 200.0
"""How far ahead of the ego the `traffic` feature describes each lane's traffic [m]."""


def traffic(
    world: WorldState, value: np.ndarray, rel_s: np.ndarray, in_row: np.ndarray, road_rows: np.ndarray
) -> np.ndarray:
    """Per row, the traffic within TRAFFIC_RANGE ahead of the ego, far beyond the grid: [mean and
    lowest `value` (each other vehicle's relative speed, `perception.grid.fill_grid`'s; 0 when there
    are none), the share of the range their lengths fill in [0, 1]]; [0, 0, 1] off the road. Tells a
    stopped lane, a truck lane and a free road apart before they reach the grid. `in_row` (rows,
    other vehicles): the rows each covers; `road_rows`: each row's road lane, -1 off the road."""
    ahead = (rel_s > 0) & (rel_s <= TRAFFIC_RANGE)
    described = np.zeros((len(road_rows), TRAFFIC_VALUES), dtype=np.float32)
    for row, lane in enumerate(road_rows):
        if lane < 0:
            described[row] = (0.0, 0.0, 1.0)
            continue
        in_lane = np.flatnonzero(ahead & in_row[row])
        if in_lane.size:
            filled = min(float(world.length[1:][in_lane].sum()) / TRAFFIC_RANGE, 1.0)
            described[row] = (value[in_lane].mean(), value[in_lane].min(), filled)
    return described


def ego_lateral(world: WorldState) -> np.ndarray:
    """[offset from the ego lane's centre / lane width, heading error / EGO_HEADING_SCALE], in [-1, 1]."""
    ego_lane = int(world.lane[0])
    lane_heading = world.lanes[ego_lane].heading_at(float(world.s[0]))
    return lateral_feature(
        world.d[0], world.lane_offsets[ego_lane], world.lane_width, world.heading[0], lane_heading
    )


def lateral_feature(
    d: float, lane_centre: float, lane_width: float, heading: float, lane_heading: float
) -> np.ndarray:
    """`ego_lateral` of an ego at lateral position `d` [m] and `heading` [rad] in a lane centred at
    `lane_centre` [m] heading `lane_heading` [rad]: float32 [offset / lane width, heading error /
    EGO_HEADING_SCALE], in [-1, 1]."""
    offset = (d - lane_centre) / lane_width
    error = np.arctan2(np.sin(heading - lane_heading), np.cos(heading - lane_heading))
    return np.clip([offset, error / EGO_HEADING_SCALE], -1, 1).astype(np.float32)
