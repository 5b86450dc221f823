"""The adaptive cruise's leaders: which vehicles ahead the ego keeps a time gap to, in its own lane
and, during a lane change, the target lane (the maneuver hands them to the controller in the
`Reference`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.extending import register_jitable

from common.neighbours import lateral_extent, swept_distance
from records import Neighbour, WorldState

LEAVING_M = 1.0
"""A leader whose centre is farther than this from the lane's centre is leaving (or entering) the
lane, and no longer hides the vehicle ahead of it [m]."""


SIDE_MARGIN_M = 0.3
"""Lateral room a passed vehicle must still have to the ego's side when the ego is by [m]."""


@register_jitable
def passes_before_reached(
    rel_s: float,
    closing: float,
    lengths: float,
    towards: float,
    speed: float,
    heading_to_lane: float,
    apart: float,
    extent: float,
    width: float,
) -> bool:
    """Whether the ego's rear passes the front of a vehicle `rel_s` [m] ahead, `closing` [m/s] slower
    and `lengths` [m] (the two half lengths) long together, before that vehicle, at its `speed`
    [m/s] and `heading_to_lane` [rad] towards the ego's side (`towards`: +-1), comes within the
    side margin of the ego: `apart` [m] is its centre's distance to the ego's side less the margin,
    `extent` [m] its turned footprint across the road, `width` [m] its width. Both keep their
    speeds. Never while its turned footprint is already that close sideways."""
    clear_s = (rel_s + lengths) / closing
    lateral = towards * speed * math.sin(heading_to_lane)
    if apart - extent / 2 <= 0:
        return False
    side_gap = apart - width / 2
    return lateral <= 0 or clear_s < side_gap / lateral


def leaders(
    world: WorldState, lanes: tuple[int, ...], cut_in_lookahead_s: float = 0.0
) -> tuple[Neighbour, ...]:
    """For each lane in `lanes`, the closest vehicle ahead reaching into it, now or within
    `cut_in_lookahead_s` [s] at its present sideways speed (a car cutting in is a leader before it
    arrives: R157's careful driver perceives a cut-in once it leaves its lane's wandering zone),
    none if nobody, and,
    while that one is leaving or entering the lane (centre more than `LEAVING_M` off the lane's
    centre), the next one ahead that it no longer hides, and so on: a cut-out reveals the car
    beyond at once. A slower vehicle entering the lane that the ego passes before it reaches
    the ego's side (`passes_before_reached`) is not followed: braking for it would only keep
    the two side by side for longer. `leaders_in_rows`, compiled, on the world's rows."""
    n = world.count
    found_most = n * len(lanes)
    gaps, speeds, rows = np.empty(found_most), np.empty(found_most), np.empty(found_most, dtype=np.int64)
    reference = world.lanes[0]
    found = _leaders_in_rows(
        np.array(lanes, dtype=np.int64), n, world.s, world.d, world.speed,
        world.heading - np.array([reference.heading_at(s) for s in world.s.tolist()]),
        world.length, world.width, np.concatenate(((0.0,), lateral_extent(world))),
        world.lane_offsets, world.lane_width, cut_in_lookahead_s, gaps, speeds, rows,
    )  # fmt: skip
    ids = world.ids
    return tuple(
        Neighbour(gap, speed, int(ids[row]))
        for gap, speed, row in zip(
            gaps[:found].tolist(), speeds[:found].tolist(), rows[:found].tolist(), strict=True
        )
    )


@register_jitable
def leaders_in_rows(
    lanes: np.ndarray,
    n: int,
    s: np.ndarray,
    d: np.ndarray,
    speed: np.ndarray,
    heading_to_lane: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    extent: np.ndarray,
    offsets: np.ndarray,
    lane_width: float,
    cut_in_lookahead_s: float,
    gaps: np.ndarray,
    speeds: np.ndarray,
    rows: np.ndarray,
) -> int:
    """`leaders(world, lanes)` of one world's `n` vehicles as rows of arrays (row 0 the ego;
    `heading_to_lane`: each one's heading to the lane at its position [rad]; `extent`: its turned
    footprint across the road [m]; `cut_in_lookahead_s` [s]: how far ahead its sideways motion,
    speed times the sine of `heading_to_lane`, counts): writes each leader's gap [m], speed [m/s]
    and row in order and returns how many."""
    found = 0
    candidates = np.empty(n, dtype=np.int64)
    for lane in lanes:
        m = 0
        for row in range(1, n):
            rel = s[row] - s[0]
            offset = abs(d[row] - offsets[lane])
            drift = speed[row] * math.sin(heading_to_lane[row]) * cut_in_lookahead_s
            across = swept_distance(d[row], drift, offsets[lane])
            if not (across < (lane_width + extent[row]) / 2 and rel > 0):
                continue
            if offset > LEAVING_M and speed[row] < speed[0]:
                towards = math.copysign(1.0, d[0] - d[row])
                apart = abs(d[row] - d[0]) - width[0] / 2 - SIDE_MARGIN_M
                if passes_before_reached(
                    rel, speed[0] - speed[row], (length[0] + length[row]) / 2, towards, speed[row],
                    heading_to_lane[row], apart, extent[row], width[row],
                ):  # fmt: skip
                    continue
            position = m
            while position > 0 and s[candidates[position - 1]] - s[0] > rel:
                candidates[position] = candidates[position - 1]
                position -= 1
            candidates[position] = row
            m += 1
        for k in range(m):
            row = candidates[k]
            gaps[found] = (s[row] - s[0]) - (length[row] + length[0]) / 2
            speeds[found], rows[found] = speed[row], row
            found += 1
            if abs(d[row] - offsets[lane]) <= LEAVING_M:
                break
    return found


_leaders_in_rows = njit(cache=True, nogil=True)(leaders_in_rows)
