"""Who is ahead in a lane: the leaders the longitudinal controller keeps a gap to."""

from __future__ import annotations

import numpy as np

from perception.types import WorldState


def leaders(world: WorldState, lanes: tuple[int, ...]) -> list[tuple[float, float]]:
    """For each lane in `lanes`, the closest vehicle ahead whose footprint reaches into that lane,
    as (bumper-to-bumper gap [m], speed [m/s]); lanes with nobody ahead are left out."""
    rel_s = world.s[1:] - world.s[0]
    gap = rel_s - (world.length[1:] + world.length[0]) / 2
    found = []
    for lane in lanes:
        reach = (world.lane_width + world.width[1:]) / 2
        in_lane = (np.abs(world.d[1:] - world.lane_offsets[lane]) < reach) & (rel_s > 0)
        if in_lane.any():
            row = np.flatnonzero(in_lane)[np.argmin(rel_s[in_lane])]
            found.append((float(gap[row]), float(world.speed[row + 1])))
    return found
