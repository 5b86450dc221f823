"""The compiled steps of a batch of closed loops (`stack.batch.closed_loop`), one call each over
every world: `decide` (a decision point: the safety layer's filter, the maneuver's lane change),
`control` (one tick's reference, leaders, PID, cruise and emergency braking: the actuation) and
`settle` (after the plant's frame: road departure, the maneuver's end). Each follows
`ClosedLoop.act` / `ClosedLoop.tick` on one world, through the per-world functions of
`controllers.batch_control` and `planner.safety`.

The state a kernel reads and writes is a tuple of arrays, one row per world (`EgoState`'s
`arrays()`): maneuver (lane, target, quintic coefficients (W, 6), profile [t0, duration, end,
peak lateral speed], clock [anchor, profile anchor, rate], counts [lane changes, masked,
aborted]), controller (lateral PID [integral, output, has output, last steering], speed PI
[integral, output, has output], emergency braking's per-vehicle memory and [active,
activations]) and the road departure flag."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from common import neighbours
from common.compiled import Kernel
from common.neighbours import VehicleRows
from controllers.batch_control import (
    coefficients,
    cruise_acceleration,
    emergency_acceleration,
    lateral_steering,
    leaders_of,
    peak_speed,
    warped_sample,
)
from controllers.reference import QUINTIC_PEAK_SPEED
from planner.safety import SafetySettings, change_is_safe, lane_is_safe
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
    c = coefficients(d0, d1, duration, v0, a0)
    for k in range(6):
        coef[w, k] = c[k]
    profile[w, 0], profile[w, 1], profile[w, 2] = t0, duration, d1
    profile[w, 3] = peak_speed(c[0], c[1], c[2], c[3], c[4], c[5], duration)
    clock[w, 0], clock[w, 1], clock[w, 2] = 0.0, 0.0, 1.0


@njit(cache=True, nogil=True)
def _sample(
    w: int, coef: np.ndarray, profile: np.ndarray, clock: np.ndarray, t: float
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    return warped_sample(
        coef[w], profile[w, 0], profile[w, 1], profile[w, 2], clock[w, 0], clock[w, 1], clock[w, 2], t
    )


@Kernel
def decide(
    live: np.ndarray,
    commands: np.ndarray,
    time: np.ndarray,
    columns: tuple[np.ndarray, ...],
    reach: np.ndarray,
    lane_width: float,
    maneuver: tuple[np.ndarray, ...],
    safety: SafetySettings,
    settings: np.ndarray,
    outcome: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`ClosedLoop.act`'s decision point in each `live` world: a command given while no lane change
    runs passes the safety layer (`safety`: `planner.safety.SafetySettings`; STAY when it
    fails: masked) to the maneuver, which starts the lane change unless it is refused
    (off the road, below the lane-change speed). `settings`: nominal lane-change duration [s],
    minimum lane-change speed [m/s], tan of the largest course. `outcome` (W, 3): considered,
    masked, refused (1 or 0)."""
    count, s, d, speed, length, _, _, lanes_count, offsets = columns
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
        goal = lane[w] + command - 1
        ego_speed = speed[w, 0]
        if command == STAY or not 0 <= goal < lanes_count[w] or ego_speed < settings[1]:
            outcome[w, 2] = 1 if command != STAY else 0
            continue
        d0, d_dot, _ = _sample(w, coef, profile, clock, time[w])
        distance = offsets[w, goal] - d0
        drive_speed = ego_speed
        if settings[1] > drive_speed:
            drive_speed = settings[1]
        if 1e-3 > drive_speed:
            drive_speed = 1e-3
        stretched = QUINTIC_PEAK_SPEED * abs(distance) / (drive_speed * settings[2])
        duration = stretched if stretched > settings[0] else settings[0]
        _set_profile(w, coef, profile, clock, d0, offsets[w, goal], time[w], duration, d_dot, 0.0)
        target[w] = goal
        counts[w, 0] += 1


@Kernel
def control(
    live: np.ndarray,
    time: np.ndarray,
    columns: tuple[np.ndarray, ...],
    heading: np.ndarray,
    lane_heading: np.ndarray,
    extent: np.ndarray,
    drift: np.ndarray,
    lane_width: float,
    slots: np.ndarray,
    maneuver: tuple[np.ndarray, ...],
    controller: tuple[np.ndarray, ...],
    safety: SafetySettings,
    settings: np.ndarray,
    gains: np.ndarray,
    dt: float,
    actuation: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`ClosedLoop.tick` up to the plant in each `live` world: the maneuver's reference (a lane
    change whose gap closed is aborted first, at the abort gap [m] and TTC [s] of `safety`, each
    vehicle counted where it reaches within its lateral `drift` [m] over the abort's lookahead), the
    leaders (of the lane it heads for, then of every other lane the ego's footprint reaches), the
    lateral PID, the adaptive cruise and emergency braking; writes (acceleration
    [m/s^2], steering [rad]) to `actuation` (W, 2). `settings`: nominal duration [s], minimum
    speed [m/s], tan of the largest course, set speed [m/s]; `gains`: the lateral PID's five, the
    cruise's six, emergency braking's three (`EgoState`); `slots` (W, rows): the column of emergency
    braking's memory each row's vehicle keeps (its id, as the per-world memory keys it)."""
    count, s, d, speed, length, width, _, lanes_count, offsets = columns
    lane, target, coef, profile, clock, counts = maneuver
    lateral, speed_pi, seen, seen_speed, seen_slowing, flags = controller
    vehicles, most_lanes = s.shape[1], offsets.shape[1]
    gaps = np.empty(most_lanes * vehicles)
    speeds = np.empty(most_lanes * vehicles)
    rows = np.empty(most_lanes * vehicles, dtype=np.int64)
    lanes = np.empty(most_lanes, dtype=np.int64)
    reach = (lane_width + extent) / 2
    for w in range(live.shape[0]):
        if not live[w]:
            continue
        t, n = time[w], count[w]
        if lane[w] != target[w]:
            crossed = abs(d[w, 0] - offsets[w, lane[w]]) > lane_width / 2
            if not crossed and safety.enabled and not lane_is_safe(
                VehicleRows(n, s[w], d[w], speed[w], length[w], reach[w], drift[w]), offsets[w, target[w]],
                safety.abort_gap_m, safety.abort_ttc_s, 0.0, 0.0,
            ):  # fmt: skip
                counts[w, 2] += 1
                _, d_dot, d_ddot = _sample(w, coef, profile, clock, t)
                target[w] = lane[w]
                home = offsets[w, lane[w]]
                _set_profile(w, coef, profile, clock, d[w, 0], home, t, settings[0] / 2, d_dot, d_ddot)
        peak = profile[w, 3]
        rate = 1.0
        if peak != 0.0:
            rate = max(speed[w, 0], 0.0) * settings[2] / peak
            rate = rate if rate < 1.0 else 1.0
        if rate != clock[w, 2]:
            clock[w, 1] = clock[w, 1] + (t - clock[w, 0]) * clock[w, 2]
            clock[w, 0], clock[w, 2] = t, rate
        lanes[0], used = target[w], 1
        low, high = ego_extent(w, d, length, width, heading, lane_heading)
        for other in range(lanes_count[w]):
            if other != target[w] and reaches_lane(low, high, offsets[w, other], lane_width):
                lanes[used] = other
                used += 1
        d_ref, d_dot_ref, d_ddot_ref = _sample(w, coef, profile, clock, t)
        found = leaders_of(
            lanes[:used], n, s[w], d[w], speed[w], heading[w], length[w], width[w], extent[w], offsets[w],
            lane_width, lane_heading[w], gaps, speeds, rows,
        )  # fmt: skip
        for k in range(found):
            rows[k] = slots[w, rows[k]]
        ego_speed = speed[w, 0]
        relative = heading[w, 0] - lane_heading[w]
        curvature = (lane_heading[w] - lane_heading[w]) / 2.0
        steering = lateral_steering(
            lateral[w], gains[:5], d[w, 0], relative, ego_speed, curvature, d_ref, d_dot_ref, d_ddot_ref, dt
        )
        acceleration = cruise_acceleration(
            speed_pi[w], gains[5:11], ego_speed, settings[3], gaps, speeds, found, dt
        )
        acceleration = emergency_acceleration(
            acceleration, ego_speed, gaps, speeds, rows, found,
            seen[w], seen_speed[w], seen_slowing[w], flags[w], gains[11:14], dt,
        )  # fmt: skip
        actuation[w, 0], actuation[w, 1] = acceleration, steering


@njit(cache=True, nogil=True)
def ego_extent(
    w: int,
    d: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    heading: np.ndarray,
    lane_heading: np.ndarray,
) -> tuple[float, float]:  # pragma: no cover - compiled
    """(lowest, highest) lateral coordinate [m] of world `w`'s ego footprint corners
    (`common.neighbours.footprint_lateral_extent`: its rectangle turned by its heading to the lane)."""
    relative = heading[w, 0] - lane_heading[w]
    half = (length[w, 0] * abs(math.sin(relative)) + width[w, 0] * abs(math.cos(relative))) / 2
    return d[w, 0] - half, d[w, 0] + half


reaches_lane = njit(cache=True, nogil=True, inline="always")(neighbours.reaches_lane)
"""`common.neighbours.reaches_lane` compiled: the one footprint-reaches-lane test of both paths."""


@Kernel
def settle(
    stepped: np.ndarray,
    time: np.ndarray,
    columns: tuple[np.ndarray, ...],
    heading: np.ndarray,
    lane_heading: np.ndarray,
    lane_width: float,
    maneuver: tuple[np.ndarray, ...],
    departed: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """After the plant's frame, in each `stepped` world: the safety monitor's road departure (a
    footprint corner more than the tolerance beyond the outer lanes' edges) and the maneuver's
    update (a lane change whose clock has run out ends: the target is the lane)."""
    _, _, d, _, length, width, _, lanes_count, offsets = columns
    lane, target, _, profile, clock, _ = maneuver
    for w in range(stepped.shape[0]):
        if not stepped[w]:
            continue
        low, high = ego_extent(w, d, length, width, heading, lane_heading)
        if departs(low, high, offsets[w], lanes_count[w], lane_width):
            departed[w] = True
        if lane[w] != target[w]:
            profile_time = clock[w, 1] + (time[w] - clock[w, 0]) * clock[w, 2]
            if profile_time - profile[w, 0] >= profile[w, 1]:
                lane[w] = target[w]
