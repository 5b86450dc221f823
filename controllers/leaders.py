"""The adaptive cruise's leaders: which vehicles ahead the ego keeps a time gap to, in its own lane
and, during a lane change, the target lane (the maneuver hands them to the controller in the
`Reference`)."""

from __future__ import annotations

import math

import numpy as np

from common.neighbours import lateral_extent
from records import Neighbour, WorldState

LEAVING_M = 1.0
"""A leader whose centre is farther than this from the lane's centre is leaving (or entering) the
lane, and no longer hides the vehicle ahead of it [m]."""


SIDE_MARGIN_M = 0.3
"""Lateral room a passed vehicle must still have to the ego's side when the ego is by [m]."""


def passed_before_reached(world: WorldState, row: int, margin: float = SIDE_MARGIN_M) -> bool:
    """Whether the ego's rear passes the front of the vehicle in `row` (slower, beside or ahead)
    before that vehicle, at its lateral speed towards the ego, comes within `margin` [m] of
    the ego's side; both keep their speeds. Never while its turned footprint
    (`lateral_extent`: a car nosing into the lane) is already that close sideways."""
    rel_s, closing = float(world.s[row] - world.s[0]), float(world.speed[0] - world.speed[row])
    clear_s = (rel_s + (world.length[0] + world.length[row]) / 2) / closing
    lane_heading = world.lanes[0].heading_at(float(world.s[row]))
    towards = math.copysign(1.0, float(world.d[0] - world.d[row]))
    lateral = towards * float(world.speed[row]) * math.sin(float(world.heading[row]) - lane_heading)
    apart = abs(float(world.d[row] - world.d[0])) - float(world.width[0]) / 2 - margin
    if apart - float(lateral_extent(world)[row - 1]) / 2 <= 0:
        return False
    side_gap = apart - float(world.width[row]) / 2
    return lateral <= 0 or clear_s < side_gap / lateral


def leaders(world: WorldState, lanes: tuple[int, ...]) -> tuple[Neighbour, ...]:
    """For each lane in `lanes`, the closest vehicle ahead reaching into it (none if nobody) and,
    while that one is leaving or entering the lane (centre more than `LEAVING_M` off the lane's
    centre), the next one ahead that it no longer hides, and so on: a cut-out reveals the car
    beyond at once. A slower vehicle entering the lane that the ego passes before it reaches
    the ego's side (`passed_before_reached`) is not followed: braking for it would only keep
    the two side by side for longer."""
    rel_s = world.s[1:] - world.s[0]
    gap = rel_s - (world.length[1:] + world.length[0]) / 2
    reach, d, ahead = (world.lane_width + lateral_extent(world)) / 2, world.d[1:], rel_s > 0
    slower = world.speed[1:] < world.speed[0]
    found: list[Neighbour] = []
    for lane in lanes:
        offset = np.abs(d - world.lane_offsets[lane])
        in_lane = (offset < reach) & ahead
        for row in (in_lane & (offset > LEAVING_M) & slower).nonzero()[0].tolist():
            in_lane[row] = not passed_before_reached(world, row + 1)
        rows = in_lane.nonzero()[0]
        for row in rows[np.argsort(rel_s[rows], kind="stable")].tolist():
            found.append(Neighbour(float(gap[row]), float(world.speed[row + 1]), int(world.ids[row + 1])))
            if offset[row] <= LEAVING_M:
                break
    return tuple(found)
