"""The adaptive cruise's leaders: which vehicles ahead the ego keeps a time gap to, in its own lane
and, during a lane change, the target lane (the maneuver hands them to the controller in the
`Reference`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.extending import register_jitable

from common.longitudinal import STOP_MARGIN_M
from common.neighbours import between_lanes, lateral_extent, swept_distance
from controllers.passing import (
    FoundLeaders,
    LeaderQuery,
    LeaderRows,
    is_listed,
    passes_it,
    passes_sooner_than_falls_back,
)
from controllers.reference import road_to_reach
from controllers.weaving import WeaveMemory, WeaveTable, note_weaves_by_id, weavers_in_rows
from records import Neighbour, WorldState

LEAVING_M = 1.0
"""A leader whose centre is farther than this from the lane's centre is leaving (or entering) the
lane, and no longer hides the vehicle ahead of it [m]."""


LEAVE_MARGIN_M = 0.3
"""How far past the origin lane's edge the ego's centre must be, beyond half its width, before its
turned footprint has left the lane [m] (a 5 m car at 3 deg reaches 0.26 m further across)."""
LEAVE_SAFETY = 1.5
"""Margin on the road a lane change still needs to leave its origin lane: a vehicle ahead there is
passed by only when it is farther than this times that road [-]."""


@register_jitable
def road_to_leave(
    coefficients: tuple[float, float, float, float, float, float],
    t0: float,
    duration: float,
    d1: float,
    profile_time: float,
    peak_lateral_speed: float,
    origin_offset: float,
    lane_width: float,
    ego_width: float,
    speed: float,
    tan_max_course: float,
) -> float:
    """Road [m] a lane change on the quintic `coefficients` (from `t0`, over `duration` [s], to
    `d1` [m]; now at `profile_time` [s] on its clock) still needs before the ego's footprint is out
    of the origin lane centred at `origin_offset` [m]: until its centre is half the lane, half the
    ego's `width` and `LEAVE_MARGIN_M` past that centre (`controllers.reference.road_to_reach`)."""
    towards = 1.0 if d1 > origin_offset else -1.0
    beyond = origin_offset + towards * (lane_width / 2 + ego_width / 2 + LEAVE_MARGIN_M)
    c0, c1, c2, c3, c4, c5 = coefficients
    return road_to_reach(
        c0, c1, c2, c3, c4, c5, t0, duration, d1, profile_time, beyond, towards, speed, tan_max_course,
        peak_lateral_speed,
    )  # fmt: skip


def leaders(
    world: WorldState,
    lanes: tuple[int, ...],
    cut_in_lookahead_s: float = 0.0,
    leaving_lane: int = -1,
    leaving_within_m: float = math.inf,
    beyond: int = -1,
    weaves: WeaveMemory | None = None,
    weaver_wary_s: float = 0.0,
) -> tuple[Neighbour, ...]:
    """For each lane in `lanes`, the closest vehicle ahead reaching into it, now or within
    `cut_in_lookahead_s` [s] at its present sideways speed (a car cutting in is a leader before it
    arrives: R157's careful driver perceives a cut-in once it leaves its lane's wandering zone),
    none if nobody, and, while that one is leaving or entering the lane (centre more than
    `LEAVING_M` off the lane's centre), the next one ahead that it no longer hides, and so on: a
    cut-out reveals the car beyond at once. A slower vehicle entering the lane that the ego passes
    (`passes_it`: past before it comes within the ego's side margin, or beside it anyway and past
    sooner than braking would bring it back, before it touches the ego's side) is not followed:
    braking for it would only keep the two side by side for longer. In `leaving_lane`
    (the lane a lane change is leaving; -1: none) a vehicle farther ahead than `LEAVE_SAFETY` times
    `leaving_within_m` [m] (the road the change still needs to leave it,
    `controllers.reference.road_to_reach`) plus the stop margin is not followed: the ego is out of
    that lane before it gets there, and stopping for it would stall the change beside it (the
    profile's clock stops with the car). Then the cars that may turn back into a lane
    (`turning_back_in_rows`) and, during a lane change, those beside the ego in the lane `beyond`
    its target (`beside_beyond_in_rows`) and the cars that weaved less than `weaver_wary_s` [s] ago
    next to the lane the ego keeps or heads for (`controllers.weaving.weavers_in_rows`, from
    `weaves`, the world's memory, noted here once a tick; none without it), marked `may_turn_back`.
    `leaders_in_rows`, compiled, on the world's `LeaderRows`."""
    n = world.count
    found_most = n * (len(lanes) + 3)
    out = FoundLeaders(np.empty(found_most), np.empty(found_most), np.empty(found_most, dtype=np.int64))
    reference = world.lanes[0]
    watched = np.array(lanes, dtype=np.int64)
    heading_to_lane = world.heading - np.array([reference.heading_at(s) for s in world.s.tolist()])
    extent = np.concatenate(((0.0,), lateral_extent(world)))
    rows_of_world = LeaderRows(
        n, world.s, world.d, world.speed, heading_to_lane, world.length, world.width, extent,
        world.lane_offsets, world.lane_width, np.full(n, math.inf),
    )  # fmt: skip
    query = LeaderQuery(watched, cut_in_lookahead_s, leaving_lane, leaving_within_m, beyond, weaver_wary_s)
    if weaves is None:
        found, held = _leaders_in_rows(rows_of_world, query, out)
    else:
        weaves.room(world.ids)
        found, held = _noted_leaders_in_rows(rows_of_world, world.time, world.ids, weaves.table, query, out)
    ids = world.ids
    return tuple(
        Neighbour(gap, speed, int(ids[row]), k >= found)
        for k, (gap, speed, row) in enumerate(
            zip(out.gaps[:held].tolist(), out.speeds[:held].tolist(), out.rows[:held].tolist(), strict=True)
        )
    )


@register_jitable
def leaders_in_rows(world: LeaderRows, query: LeaderQuery, out: FoundLeaders) -> tuple[int, int]:
    """`leaders(world, lanes)` of one world's rows, as `query` asks (a vehicle's sideways motion is
    its speed times the sine of its `heading_to_lane`): writes into `out` each leader's gap [m],
    speed [m/s] and row in order, then those of the cars that may turn back
    (`turning_back_in_rows`), are beside the ego in the lane beyond (`beside_beyond_in_rows`) or
    weaved lately (`controllers.weaving.weavers_in_rows`), and returns (how many leaders, how many
    in all): the cruise keeps its gap to all, emergency braking reads the leaders only."""
    s, d, speed, length, offsets = world.s, world.d, world.speed, world.length, world.lane_offsets
    lanes, cut_in_lookahead_s, leaving_lane, leaving_within_m, beyond, weaver_wary_s = query
    gaps, speeds, rows = out
    found = 0
    candidates = np.empty(world.vehicles, dtype=np.int64)
    heading_for = offsets[lanes[0]] if len(lanes) > 0 else d[0]
    for lane in lanes:
        m = 0
        for row in range(1, world.vehicles):
            rel = s[row] - s[0]
            offset = abs(d[row] - offsets[lane])
            drift = speed[row] * math.sin(world.heading_to_lane[row]) * cut_in_lookahead_s
            across = swept_distance(d[row], drift, offsets[lane])
            if not (across < (world.lane_width + world.extent[row]) / 2 and rel > 0):
                continue
            gap = rel - (length[row] + length[0]) / 2
            if lane == leaving_lane and gap > LEAVE_SAFETY * leaving_within_m + STOP_MARGIN_M:
                continue
            if offset > LEAVING_M and passes_it(world, row, rel, cut_in_lookahead_s, heading_for):
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
    held = turning_back_in_rows(world, lanes, cut_in_lookahead_s, heading_for, found, out)
    held = beside_beyond_in_rows(world, beyond, cut_in_lookahead_s, held, out)
    return found, weavers_in_rows(world, heading_for, weaver_wary_s, held, out)


@register_jitable
def turning_back_in_rows(
    world: LeaderRows,
    lanes: np.ndarray,
    cut_in_lookahead_s: float,
    heading_for: float,
    found: int,
    out: FoundLeaders,
) -> int:
    """Appends to the `found` leaders in `out` (`leaders_in_rows`) each vehicle that is between
    lanes (its centre farther than R157's wandering zone, `WANDERING_M`, from every lane centre)
    within the road the ego covers in `cut_in_lookahead_s` [s], and that would reach into a lane of
    `lanes` in that time if it turned back at its present sideways speed; returns the new count. A
    car weaving at a lane boundary close ahead, moving away, may turn back into the lane the ego
    is about to fill: the cruise keeps its time gap to it (the ego does not accelerate into the gap
    it leaves), but emergency braking waits until it does turn in (`leaders_in_rows` finds it then),
    so no cut-out close ahead is a full brake. One moving towards a lane that the ego passes
    (`passes_it`, on the ego's way to `heading_for` [m]) is let go there, as the cut-in rule lets
    it go: held, the cruise fell back beside it into its path."""
    s, d, speed, length, offsets = world.s, world.d, world.speed, world.length, world.lane_offsets
    gaps, speeds, rows = out
    total = found
    close = speed[0] * cut_in_lookahead_s
    for row in range(1, world.vehicles):
        rel = s[row] - s[0]
        lengths = (length[row] + length[0]) / 2
        if not 0 < rel < close + lengths:
            continue
        if not between_lanes(d[row], offsets) or is_listed(rows, found, row):
            continue
        sideways = speed[row] * math.sin(world.heading_to_lane[row])
        reach = abs(sideways) * cut_in_lookahead_s
        passed = passes_it(world, row, rel, cut_in_lookahead_s, heading_for)
        for lane in lanes:
            if passed and sideways * (offsets[lane] - d[row]) > 0:
                continue
            back = math.copysign(reach, offsets[lane] - d[row])
            if swept_distance(d[row], back, offsets[lane]) < (world.lane_width + world.extent[row]) / 2:
                gaps[total], speeds[total], rows[total] = rel - lengths, speed[row], row
                total += 1
                break
    return total


@register_jitable
def beside_beyond_in_rows(
    world: LeaderRows,
    beyond: int,
    cut_in_lookahead_s: float,
    found: int,
    out: FoundLeaders,
) -> int:
    """Appends to the `found` leaders in `out` (`leaders_in_rows`) each vehicle in lane
    `beyond`, the lane beyond the one a lane change heads for (-1: no change runs), that is ahead
    of the ego (its centre ahead of the ego's) and beside it or reached within
    `cut_in_lookahead_s` [s] at their present speeds, unless the ego passes it sooner than it could
    fall back (`passes_sooner_than_falls_back`); returns the new count. Beside the ego it may take
    the same lane at the same moment (a driver who does not see the ego turns into its side), so
    the cruise keeps its time gap to it (the ego does not pace it while it changes lane) and
    emergency braking waits until it does turn in, as for a car that may turn back."""
    s, speed, length = world.s, world.speed, world.length
    gaps, speeds, rows = out
    total = found
    if beyond < 0:
        return total
    for row in range(1, world.vehicles):
        rel = s[row] - s[0]
        if rel <= 0 or abs(world.d[row] - world.lane_offsets[beyond]) > world.lane_width / 2:
            continue
        lengths = (length[row] + length[0]) / 2
        closing = speed[0] - speed[row]
        gap = rel - lengths
        if gap >= max(closing, 0.0) * cut_in_lookahead_s:
            continue
        if closing > 0 and passes_sooner_than_falls_back(rel, closing, lengths):
            continue
        if not is_listed(rows, total, row):
            gaps[total], speeds[total], rows[total] = gap, speed[row], row
            total += 1
    return total


_leaders_in_rows = njit(cache=True, nogil=True)(leaders_in_rows)


@njit(cache=True, nogil=True)
def _noted_leaders_in_rows(
    world: LeaderRows, time: float, ids: np.ndarray, table: WeaveTable, query: LeaderQuery, out: FoundLeaders
) -> tuple[int, int]:  # pragma: no cover - compiled
    """One world's tick of its weave memory (`note_weaves_by_id`: the vehicles' `ids`, the memory's
    `table`) and then `leaders_in_rows`, in one compiled call."""
    note_weaves_by_id(world, time, ids, table)
    return leaders_in_rows(world, query, out)
