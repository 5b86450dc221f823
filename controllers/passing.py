"""What the leaders' laws read and the tests of a pass: one world's rows (`LeaderRows`), where the
leaders found are written (`FoundLeaders`), and whether the ego passes a vehicle rather than
following it (`passes_it` and its parts), shared by the leaders of a lane (`controllers.leaders`)
and the vehicles the cruise alone keeps a gap to (`controllers.weaving`)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable


class LeaderRows(NamedTuple):
    """One world's `vehicles` as the leaders' laws read them, a row each, row 0 the ego: centres `s`
    and `d` [m] in lane 0's frame, `speed` [m/s], heading to the lane at its position,
    `heading_to_lane` [rad], `length` and `width` [m], turned footprint across the road, `extent`
    [m] (`common.neighbours.lateral_extent`; the ego's never read); lane k's centre at
    `lane_offsets[k]`, each lane `lane_width` [m] wide; `weaved_s` [s], how long ago each row's
    vehicle last turned back in the middle of a lane change (`controllers.weaving`; inf: never or
    unknown). Made once a tick, by `leaders` for one world and by the batch's control kernel for
    each of its worlds."""

    vehicles: int
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    heading_to_lane: np.ndarray
    length: np.ndarray
    width: np.ndarray
    extent: np.ndarray
    lane_offsets: np.ndarray
    lane_width: float
    weaved_s: np.ndarray


class LeaderQuery(NamedTuple):
    """What `controllers.leaders.leaders_in_rows` looks for in one world this tick: the `lanes` it
    watches (the one the ego keeps or heads for first), how far ahead a vehicle's sideways motion
    counts, `cut_in_lookahead_s` [s], the lane a lane change is leaving, `leaving_lane` (-1: none),
    and the road it still needs to leave it, `leaving_within_m` [m], the lane `beyond` the change's
    target (-1: none), and how long a vehicle that weaved stays the cruise's leader,
    `weaver_wary_s` [s] (0: not at all)."""

    lanes: np.ndarray
    cut_in_lookahead_s: float
    leaving_lane: int
    leaving_within_m: float
    beyond: int
    weaver_wary_s: float


class FoundLeaders(NamedTuple):
    """Where `leaders_in_rows` writes the vehicles it finds, in order, one entry each: the gap
    `gaps` [m] from the ego's front to its rear, its `speeds` [m/s] and its row in `LeaderRows`,
    `rows`. Room for every row in every watched lane and the three lists the cruise alone keeps."""

    gaps: np.ndarray
    speeds: np.ndarray
    rows: np.ndarray


SIDE_MARGIN_M = 0.3
"""Lateral room a passed vehicle must still have to the ego's side when the ego is by [m]."""


@register_jitable
def passes_before_it_closes_sideways(
    rel_s: float,
    closing: float,
    lengths: float,
    towards: float,
    speed: float,
    heading_to_lane: float,
    apart: float,
    width: float,
) -> bool:
    """Whether the ego's rear passes the front of a vehicle `rel_s` [m] ahead, `closing` [m/s] slower
    and `lengths` [m] (the two half lengths) long together, before that vehicle, at its `speed`
    [m/s] and `heading_to_lane` [rad] towards the ego's side (`towards`: +-1), comes within the
    side margin of the ego: `apart` [m] is its centre's distance to the ego's side less the margin,
    `width` [m] its width. Both keep their speeds; always when it does not move towards the ego."""
    clear_s = (rel_s + lengths) / closing
    lateral = towards * speed * math.sin(heading_to_lane)
    return lateral <= 0 or clear_s < (apart - width / 2) / lateral


FALL_BACK_MPS2 = 5.0
"""The braking a fall back behind a vehicle alongside is reckoned at [m/s^2]: the plant's authority,
emergency braking's default."""


@register_jitable
def passes_sooner_than_falls_back(rel_s: float, closing: float, lengths: float) -> bool:
    """Whether the ego, `closing` [m/s] faster than a vehicle `rel_s` [m] ahead (centres; `lengths`
    the two half lengths [m]), will be beside it whatever it does (its front already past the
    other's rear, or braking at `FALL_BACK_MPS2` cannot stop it short of that rear) and is past
    it (its rear beyond the other's front, at constant speeds) sooner than braking brings its front
    back behind the other's rear. Then braking for it would only hold the two side by side for
    longer."""
    past_its_rear = lengths - rel_s
    reach = closing * closing + 2 * FALL_BACK_MPS2 * past_its_rear
    if reach < 0:
        return False
    passing_s = (rel_s + lengths) / closing
    falling_back_s = (closing + math.sqrt(reach)) / FALL_BACK_MPS2
    return passing_s < falling_back_s


@register_jitable
def passes_it(world: LeaderRows, row: int, rel: float, lookahead_s: float, heading_for: float) -> bool:
    """Whether the ego, faster than the vehicle in `row` `rel` [m] ahead, passes it rather than
    following it, on its way across to `heading_for` [m] (the centre of the lane it keeps or is to
    head for, the first the leaders watch; the ego's side is where that way comes closest to the
    vehicle: a car reaching into the target lane is judged from that lane's centre, not from where
    the ego is now): the vehicle's turned footprint keeps clear of the ego's side margin and the
    ego is past before the vehicle comes within it (`passes_before_it_closes_sideways`); or the ego
    reaches the vehicle's rear within `lookahead_s` [s] at their present speeds (as far ahead as a
    sideways motion counts), will be beside it whatever it does, and passing ends that sooner
    than braking (`passes_sooner_than_falls_back`), and the vehicle, not touching the ego's side,
    does not touch it before the ego is past (the same test without the margin). The second
    settles a pass that a few centimetres of the vehicle's drift would otherwise turn into a full
    braking beside it, held there longer. The cut-in rule lets such a vehicle go, and so does the
    rule for cars that may turn back."""
    d, speed, length = world.d, world.speed, world.length
    if speed[row] >= speed[0]:
        return False
    closest = min(max(d[row], min(d[0], heading_for)), max(d[0], heading_for))
    towards = math.copysign(1.0, closest - d[row])
    to_side = abs(d[row] - closest) - world.width[0] / 2
    closing, lengths = speed[0] - speed[row], (length[0] + length[row]) / 2
    heading, width, extent = world.heading_to_lane[row], world.width[row], world.extent[row]
    apart = to_side - SIDE_MARGIN_M
    if apart - extent / 2 > 0 and passes_before_it_closes_sideways(
        rel, closing, lengths, towards, speed[row], heading, apart, width
    ):
        return True
    return (
        rel - lengths < closing * lookahead_s
        and to_side - extent / 2 > 0
        and passes_sooner_than_falls_back(rel, closing, lengths)
        and passes_before_it_closes_sideways(
            rel, closing, lengths, towards, speed[row], heading, to_side, width
        )
    )


@register_jitable
def is_listed(rows: np.ndarray, count: int, row: int) -> bool:
    """Whether `row` is among the first `count` leaders' `rows`."""
    for k in range(count):
        if rows[k] == row:
            return True
    return False
