"""The compiled steps of a batch of closed loops (`stack.batch.closed_loop_batch`), one call each over
every world: `decide` (a decision point: the safety layer's filter, the maneuver's lane change),
`control` (one tick's reference, leaders, PID, cruise and emergency braking: the actuation) and
`settle` (after the plant's frame: road departure, the maneuver's end). Each follows
`ClosedLoop.act` / `ClosedLoop.tick` on one world, through the per-world functions of
the layers' per-tick laws (`controllers`, `planner.safety`), compiled.

The state a kernel reads and writes is a tuple of arrays, one row per world (`EgoState`'s
`arrays()`): maneuver (lane, target, quintic coefficients (W, 6), profile [t0, duration, end,
peak lateral speed], clock [anchor, profile anchor, rate], counts [lane changes, masked,
aborted]), controller (lateral PID [integral, output, has output, last steering], speed PI
[integral, output, has output], emergency braking's per-vehicle memory and [active,
activations, slot braked for]) and the road departure flag."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from common.compiled import Kernel, clip
from common.longitudinal import BrakingLimits, gap_acceleration, needs_full_braking
from common.neighbours import VehicleRows, footprint_across, lane_beyond, reaches_lane
from controllers.emergency import braked_acceleration, braked_before, holds_braking, leader_braking
from controllers.lateral import LateralMemory, lateral_steering
from controllers.leaders import FoundLeaders, LeaderQuery, LeaderRows, leaders_in_rows, road_to_leave
from controllers.maneuver import lane_change_target, left_origin, settled
from controllers.pid import PIDMemory, pid_output
from controllers.reference import (
    WarpClock,
    clock_rate,
    quintic_coefficients,
    quintic_peak_speed,
    rewarped,
    stretched_duration,
    warped_sample,
    warped_time,
)
from controllers.weaving import note_weaves
from planner.safety import SafetySettings, change_is_safe, turning_back_is_safer
from records.batch import BatchColumns
from stack.batch.ego_records import ControllerArrays, EgoLaws, ManeuverArrays, ManeuverSettings
from stack.loop.safety_metrics import departs

STAY = 1
"""`Command.STAY`'s value (LEFT 0, RIGHT 2: the lane shift is the value - 1)."""


@njit(cache=True, nogil=True)
def _set_profile(
    w: int,
    coef: np.ndarray,
    profile: np.ndarray,
    clock: np.ndarray,
    d0: float,
    d1: float,
    t0: float,
    duration: float,
    v0: float,
    a0: float,
) -> None:  # pragma: no cover - compiled
    """World `w`'s maneuver takes the quintic from (d0, v0, a0) at t0 to d1 over `duration` on a
    fresh clock (`WarpedProfile(QuinticProfile(...))`)."""
    c = quintic_coefficients(d0, d1, duration, v0, a0)
    for k in range(6):
        coef[w, k] = c[k]
    profile[w, 0], profile[w, 1], profile[w, 2] = t0, duration, d1
    profile[w, 3] = quintic_peak_speed(c[0], c[1], c[2], c[3], c[4], c[5], duration)
    clock[w, 0], clock[w, 1], clock[w, 2] = 0.0, 0.0, 1.0


@njit(cache=True, nogil=True)
def _sample(
    w: int, coef: np.ndarray, profile: np.ndarray, clock: np.ndarray, t: float
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    c = coef[w]
    warp = WarpClock(clock[w, 0], clock[w, 1], clock[w, 2])
    return warped_sample(
        c[0], c[1], c[2], c[3], c[4], c[5], profile[w, 0], profile[w, 1], profile[w, 2], warp, t
    )


@Kernel
def decide(
    live: np.ndarray,
    commands: np.ndarray,
    time: np.ndarray,
    columns: BatchColumns,
    reach: np.ndarray,
    lane_width: float,
    maneuver: ManeuverArrays,
    safety: SafetySettings,
    settings: ManeuverSettings,
    outcome: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`ClosedLoop.act`'s decision point in each `live` world: a command given while no lane change
    runs passes the safety layer (`safety`: `planner.safety.SafetySettings`; STAY when it
    fails: masked) to the maneuver, which starts the lane change unless it is refused
    (off the road, below the lane-change speed). `settings`: nominal lane-change duration [s],
    minimum lane-change speed [m/s], tan of the largest course. `outcome` (W, 3): considered,
    masked, refused (1 or 0)."""
    count, s, d, speed, length = columns.vehicles, columns.s, columns.d, columns.speed, columns.length
    lanes_count, offsets = columns.lanes_count, columns.lane_offsets
    lane, target, coef, profile, clock, counts = maneuver
    now = np.zeros(s.shape[1])
    for w in range(live.shape[0]):
        outcome[w, 0] = outcome[w, 1] = outcome[w, 2] = 0
        if not live[w] or lane[w] != target[w]:
            continue
        outcome[w, 0] = 1
        command = commands[w]
        permits = True
        if command != STAY and safety.enabled:
            permits = change_is_safe(
                VehicleRows(count[w], s[w], d[w], speed[w], length[w], reach[w], now), offsets[w],
                lanes_count[w], lane[w], lane[w] + command - 1, safety,
            )  # fmt: skip
        if not permits:
            counts[w, 1] += 1
            outcome[w, 1] = 1
            continue
        ego_speed = speed[w, 0]
        d0, d_dot, _ = _sample(w, coef, profile, clock, time[w])
        at_centre = settled(d0, offsets[w, lane[w]])
        goal = lane_change_target(
            lane[w], command - 1, lanes_count[w], ego_speed, settings.min_speed, at_centre
        )
        if goal < 0:
            outcome[w, 2] = 1 if command != STAY else 0
            continue
        distance = offsets[w, goal] - d0
        duration = stretched_duration(
            distance, max(ego_speed, settings.min_speed, 1e-3), settings.duration, settings.tan_max_course
        )
        _set_profile(w, coef, profile, clock, d0, offsets[w, goal], time[w], duration, d_dot, 0.0)
        target[w] = goal
        counts[w, 0] += 1


@Kernel
def control(
    live: np.ndarray,
    time: np.ndarray,
    columns: BatchColumns,
    heading: np.ndarray,
    lane_heading: np.ndarray,
    extent: np.ndarray,
    drift: np.ndarray,
    lane_width: float,
    slots: np.ndarray,
    maneuver: ManeuverArrays,
    controller: ControllerArrays,
    safety: SafetySettings,
    settings: ManeuverSettings,
    laws: EgoLaws,
    dt: float,
    actuation: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`ClosedLoop.tick` up to the plant in each `live` world: the maneuver's reference (a lane
    change whose gap closed, its origin lane's not, is aborted first, at the abort gap [m] and TTC
    [s] of `safety` (`turning_back_is_safer`), each vehicle counted where it reaches within its
    lateral `drift` [m] over the abort's lookahead), the
    leaders (of the lane it heads for, then of every other lane the ego's footprint reaches), the
    lateral PID, the adaptive cruise and emergency braking, each the per-world law on the world's
    row; writes (acceleration [m/s^2], steering [rad]) to `actuation` (W, 2). `settings`: nominal
    duration [s], minimum speed [m/s], tan of the largest course, set speed [m/s]; `slots` (W,
    rows): the column of emergency braking's memory and of the weave memory each row's vehicle keeps
    (its id, as the per-world memories key it)."""
    count, s, d, speed = columns.vehicles, columns.s, columns.d, columns.speed
    length, width, lanes_count, offsets = (
        columns.length,
        columns.width,
        columns.lanes_count,
        columns.lane_offsets,
    )
    lane, target, coef, profile, clock, counts = maneuver
    lateral, speed_pi, seen, seen_speed, seen_slowing, flags, moving, weaved_at = controller
    vehicles, most_lanes = s.shape[1], offsets.shape[1]
    gaps = np.empty((most_lanes + 3) * vehicles)
    speeds = np.empty((most_lanes + 3) * vehicles)
    rows = np.empty((most_lanes + 3) * vehicles, dtype=np.int64)
    weaved_s = np.empty(vehicles)
    found_leaders = FoundLeaders(gaps, speeds, rows)
    lanes = np.empty(most_lanes, dtype=np.int64)
    heading_to_lane = np.empty(vehicles)
    reach = (lane_width + extent) / 2
    for w in range(live.shape[0]):
        if not live[w]:
            continue
        t, n = time[w], count[w]
        if lane[w] != target[w]:
            crossed = left_origin(d[w, 0], offsets[w, lane[w]], lane_width)
            if not crossed and safety.enabled and turning_back_is_safer(
                VehicleRows(n, s[w], d[w], speed[w], length[w], reach[w], drift[w]), offsets[w, lane[w]],
                offsets[w, target[w]], safety.abort_gap_m, safety.abort_ttc_s,
            ):  # fmt: skip
                counts[w, 2] += 1
                _, d_dot, d_ddot = _sample(w, coef, profile, clock, t)
                target[w] = lane[w]
                home = offsets[w, lane[w]]
                _set_profile(w, coef, profile, clock, d[w, 0], home, t, settings.duration / 2, d_dot, d_ddot)
        warp = rewarped(
            WarpClock(clock[w, 0], clock[w, 1], clock[w, 2]),
            t,
            clock_rate(speed[w, 0], settings.tan_max_course, profile[w, 3]),
        )
        clock[w, 0], clock[w, 1], clock[w, 2] = warp
        lanes[0], used = target[w], 1
        low, high = footprint_across(d[w, 0], length[w, 0], width[w, 0], heading[w, 0] - lane_heading[w])
        for other in range(lanes_count[w]):
            if other != target[w] and reaches_lane(low, high, offsets[w, other], lane_width):
                lanes[used] = other
                used += 1
        d_ref, d_dot_ref, d_ddot_ref = _sample(w, coef, profile, clock, t)
        for row in range(n):
            heading_to_lane[row] = heading[w, row] - lane_heading[w]
        leaving_lane, leaving_within, beyond = -1, math.inf, -1
        if lane[w] != target[w]:
            beyond = lane_beyond(lane[w], target[w], lanes_count[w])
            c = coef[w]
            leaving_lane, leaving_within = lane[w], road_to_leave(
                (c[0], c[1], c[2], c[3], c[4], c[5]), profile[w, 0], profile[w, 1], profile[w, 2],
                warped_time(warp, t), profile[w, 3], offsets[w, lane[w]], lane_width, width[w, 0],
                speed[w, 0], settings.tan_max_course,
            )  # fmt: skip
        world = LeaderRows(
            n, s[w], d[w], speed[w], heading_to_lane, length[w], width[w], extent[w], offsets[w], lane_width,
            weaved_s,
        )  # fmt: skip
        note_weaves(world, t, slots[w], moving[w], weaved_at[w])
        query = LeaderQuery(
            lanes[:used],
            settings.cut_in_lookahead_s,
            leaving_lane,
            leaving_within,
            beyond,
            settings.weaver_wary_s,
        )
        found, held = leaders_in_rows(world, query, found_leaders)
        for k in range(held):
            rows[k] = slots[w, rows[k]]
        ego_speed = speed[w, 0]
        memory = LateralMemory(
            PIDMemory(lateral[w, 0], lateral[w, 1], lateral[w, 2] != 0.0), lateral[w, 3], 0.0, False
        )
        steering, memory = lateral_steering(
            laws.lateral, memory, d[w, 0], heading[w, 0] - lane_heading[w], ego_speed, 0.0,
            d_ref, d_dot_ref, d_ddot_ref, dt, False,
        )  # fmt: skip
        lateral[w, 0], lateral[w, 1], lateral[w, 2], lateral[w, 3] = (
            memory.lateral.integral,
            memory.lateral.output,
            1.0,
            memory.steering,
        )
        acceleration = cruise_acceleration(
            speed_pi[w], laws, ego_speed, settings.set_speed, gaps, speeds, held, dt
        )
        acceleration = emergency_acceleration(
            acceleration, ego_speed, gaps, speeds, rows, found,
            seen[w], seen_speed[w], seen_slowing[w], flags[w], laws.braking, dt,
        )  # fmt: skip
        actuation[w, 0], actuation[w, 1] = acceleration, steering


@njit(cache=True, nogil=True)
def cruise_acceleration(
    state: np.ndarray,
    laws: EgoLaws,
    speed: float,
    set_speed: float,
    gaps: np.ndarray,
    speeds: np.ndarray,
    leaders: int,
    dt: float,
) -> float:  # pragma: no cover - compiled
    """`AdaptiveCruise.update` on one world's row: the speed PI (`state`: [integral, output, has
    output]) capped by the gap law of each of the first `leaders` (gap [m], speed [m/s])."""
    command, memory = pid_output(
        laws.speed, PIDMemory(state[0], state[1], state[2] != 0.0), set_speed - speed, 0.0, dt, 0.0
    )
    state[0], state[1], state[2] = memory.integral, memory.output, 1.0
    for k in range(leaders):
        command = min(command, gap_acceleration(laws.gap, speed, gaps[k], speeds[k]))
    return clip(command, laws.speed.low, laws.speed.high)


@njit(cache=True, nogil=True)
def emergency_acceleration(
    acceleration: float,
    speed: float,
    gaps: np.ndarray,
    speeds: np.ndarray,
    rows: np.ndarray,
    leaders: int,
    seen: np.ndarray,
    seen_speed: np.ndarray,
    seen_slowing: np.ndarray,
    flags: np.ndarray,
    limits: BrakingLimits,
    dt: float,
) -> float:  # pragma: no cover - compiled
    """`EmergencyBraking.apply` on one world's row: its memory per vehicle slot (`seen` 1 where it
    was a leader last tick, its speed then in `seen_speed`; 2 where it was one the tick before too,
    its slowing then in `seen_slowing` [m/s^2]) and `flags` = [active, activations, the slot of the
    vehicle the latest activation braked for]."""
    braking = np.zeros(leaders)
    rates = np.zeros(leaders)
    rated = np.zeros(leaders, dtype=np.bool_)
    for k in range(leaders):
        row = rows[k]
        if seen[row] >= 1:
            previous_slowing = seen_slowing[row] if seen[row] == 2 else 0.0
            rates[k], braking[k] = leader_braking(seen_speed[row], speeds[k], previous_slowing, dt)
            rated[k] = True
    seen[:] = 0
    for k in range(leaders):
        seen_speed[rows[k]] = speeds[k]
        seen[rows[k]] = 1
    for k in range(leaders):
        if rated[k]:
            seen_slowing[rows[k]] = rates[k]
            seen[rows[k]] = 2
    if flags[0] != 0:
        holds = False
        for k in range(leaders):
            holds = holds or holds_braking(speed, gaps[k], speeds[k])
        flags[0] = 1 if holds else 0
    else:
        for k in range(leaders):
            if needs_full_braking(limits, speed, gaps[k], speeds[k], braking[k]):
                flags[0] = 1
                flags[1] += 1
                flags[2] = rows[k]
                break
    for k in range(leaders):
        acceleration = braked_before(limits, acceleration, speed, gaps[k], speeds[k], braking[k])
    return braked_acceleration(limits, flags[0] != 0, acceleration, speed, dt)


@Kernel
def settle(
    stepped: np.ndarray,
    time: np.ndarray,
    columns: BatchColumns,
    heading: np.ndarray,
    lane_heading: np.ndarray,
    lane_width: float,
    maneuver: ManeuverArrays,
    departed: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """After the plant's frame, in each `stepped` world: the safety monitor's road departure (a
    footprint corner more than the tolerance beyond the outer lanes' edges) and the maneuver's
    update (a lane change whose clock has run out ends: the target is the lane)."""
    d, length, width = columns.d, columns.length, columns.width
    lanes_count, offsets = columns.lanes_count, columns.lane_offsets
    lane, target, profile, clock = maneuver.lane, maneuver.target, maneuver.profile, maneuver.clock
    for w in range(stepped.shape[0]):
        if not stepped[w]:
            continue
        low, high = footprint_across(d[w, 0], length[w, 0], width[w, 0], heading[w, 0] - lane_heading[w])
        if departs(low, high, offsets[w], lanes_count[w], lane_width):
            departed[w] = True
        if lane[w] != target[w]:
            profile_time = warped_time(WarpClock(clock[w, 0], clock[w, 1], clock[w, 2]), time[w])
            if profile_time - profile[w, 0] >= profile[w, 1]:
                lane[w] = target[w]
