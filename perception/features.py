"""The grid's optional features (`GridConfig.features`), computed from the same world and masks as
the presence grid: per-cell relative speed, per-row time-to-collision, the ego's lateral state, per-row
traffic ahead."""

from __future__ import annotations

import numpy as np

from records import EGO_HEADING_SCALE, TRAFFIC_VALUES, GridConfig, WorldState

TRAFFIC_RANGE = 200.0
"""How far ahead of the ego the `traffic` feature describes each lane's traffic [m]."""


def relative_speed(
    config: GridConfig,
    value: np.ndarray,
    rel_s: np.ndarray,
    along: np.ndarray,
    across: np.ndarray,
    road_rows: np.ndarray,
) -> np.ndarray:
    """Per cell, the nearest occupant's `value` (its `relative_longitudinal_speed`)."""
    grid = np.zeros((len(road_rows), config.cells), dtype=np.float32)
    for vehicle in np.argsort(-np.abs(rel_s)):
        for row, lane in enumerate(road_rows):
            if lane >= 0 and across[vehicle, lane]:
                grid[row, along[vehicle]] = value[vehicle]
    return grid


def traffic(
    world: WorldState, value: np.ndarray, rel_s: np.ndarray, across: np.ndarray, road_rows: np.ndarray
) -> np.ndarray:
    """Per row, the traffic within TRAFFIC_RANGE ahead of the ego, far beyond the grid: [mean and
    lowest `value` (the vehicles' `relative_longitudinal_speed`; 0 when there are none), the share
    of the range their lengths fill in [0, 1]]; [0, 0, 1] off the road. Tells a stopped lane, a truck
    lane and a free road apart before they reach the grid."""
    ahead = (rel_s > 0) & (rel_s <= TRAFFIC_RANGE)
    described = np.zeros((len(road_rows), TRAFFIC_VALUES), dtype=np.float32)
    for row, lane in enumerate(road_rows):
        if lane < 0:
            described[row] = (0.0, 0.0, 1.0)
            continue
        in_lane = np.flatnonzero(ahead & across[:, lane])
        if in_lane.size:
            filled = min(float(world.length[1:][in_lane].sum()) / TRAFFIC_RANGE, 1.0)
            described[row] = (value[in_lane].mean(), value[in_lane].min(), filled)
    return described


def time_to_collision(
    config: GridConfig, world: WorldState, rel_s: np.ndarray, across: np.ndarray, road_rows: np.ndarray
) -> np.ndarray:
    """Per row, min(TTC with the nearest vehicle ahead the ego closes on, horizon) / horizon; 0 off
    the road."""
    gap = rel_s - (world.length[1:] + world.length[0]) / 2
    closing = world.speed[0] - world.speed[1:]
    ttc = np.ones(len(road_rows), dtype=np.float32)
    for row, lane in enumerate(road_rows):
        if lane < 0:
            ttc[row] = 0.0
            continue
        ahead = np.flatnonzero(across[:, lane] & (rel_s > 0))
        if ahead.size:
            nearest = ahead[np.argmin(rel_s[ahead])]
            if closing[nearest] > 0:
                seconds = max(gap[nearest], 0.0) / closing[nearest]
                ttc[row] = min(seconds, config.ttc_horizon) / config.ttc_horizon
    return ttc


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


def relative_longitudinal_speed(config: GridConfig, world: WorldState) -> np.ndarray:
    """Per vehicle, its speed along the lane heading at the ego minus the ego's / speed_scale, in
    [-1, 1]."""
    lane_heading = world.lanes[0].heading_at(float(world.s[0]))
    longitudinal = world.speed * np.cos(world.heading - lane_heading)
    return np.clip((longitudinal[1:] - longitudinal[0]) / config.speed_scale, -1, 1)
