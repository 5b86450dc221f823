"""Hand-built scenes: WorldState on a straight highway-env road, without running the simulator."""

from __future__ import annotations

import numpy as np
from highway_env.road.road import RoadNetwork

from records import WorldState

LANE_WIDTH = 4.0


def straight_lanes(count: int):
    network = RoadNetwork.straight_road_network(count, length=10000)
    return tuple(network.graph["0"]["1"])


def scene(
    lanes: int,
    ego: tuple[float, int],
    others: list[tuple[float, float]] = (),
    speed: float = 25.0,
    other_speed: float = 20.0,
    length: float = 5.0,
    width: float = 2.0,
    time: float = 0.0,
) -> WorldState:
    """Ego at (x, lane); others at (x [m], y [m]) on a straight road with `lanes` lanes."""
    positions = [(ego[0], ego[1] * LANE_WIDTH)] + list(others)
    n = len(positions)
    position = np.array(positions, dtype=float)
    speeds = np.array([speed] + [other_speed] * (n - 1), dtype=float)
    lane_ids = np.clip(np.round(position[:, 1] / LANE_WIDTH), 0, lanes - 1).astype(int)
    return WorldState(
        time=time,
        ids=np.arange(n),
        position=position,
        heading=np.zeros(n),
        speed=speeds,
        velocity=np.stack([speeds, np.zeros(n)], axis=1),
        lane=lane_ids,
        length=np.full(n, length),
        width=np.full(n, width),
        s=position[:, 0].copy(),
        d=position[:, 1].copy(),
        crashed=np.zeros(n, dtype=bool),
        lanes=straight_lanes(lanes),
        lane_offsets=np.arange(lanes) * LANE_WIDTH,
    )


def cutting_in(heading_rad: float) -> WorldState:
    """Ego in lane 0 of 3, 8 m/s; a 3 m/s car 6 m ahead (gap 1 m) in lane 2, turned by
    `heading_rad` (negative: towards lane 1). Turned 0.3 rad its footprint reaches 3.7 m across:
    4 m from lane 1's centre it is not in lane 1 yet."""
    world = scene(3, (0.0, 0), [(6.0, 8.0)], speed=8.0, other_speed=3.0)
    heading = np.array([0.0, heading_rad])
    return type(world)(**{**world.__dict__, "heading": heading})
