"""The lookahead's forecast: every candidate command rolled out at once, in one loop over
(commands x steps x vehicles), a plain function that numba compiles into the lookahead's decision
(`planner.lookahead`, one world or a batch of them).

The ego follows a reduced model of the stack's own maneuver and longitudinal control: the quintic
lane change (minimum-jerk, `duration` s, tracked exactly: no controller lag), the adaptive cruise's
law (speed P term towards the set speed, capped by the constant-time-gap law for the leader of the
own lane and, during a change, of the target lane: `common.longitudinal.gap_acceleration`; the PI's
integral and the plant's lag left out) and emergency braking (full braking when comfort braking
cannot stop in the gap, or the TTC is below its trigger: `common.longitudinal.needs_full_braking`
for a leader not seen braking). The others drive IDM along the lane they are seen in, with their
desired speed set to the speed they are seen at (so a free vehicle keeps its velocity, one behind a
slower vehicle or the ego brakes): nothing but perceived state. Their IDM is the original one
(`IDM_*` below: desired gap d0 + max(0, v T + v dv / 2 sqrt(a b)), the desired speed at least
1 m/s), not the traffic's highway-env form (`stack.sim.vector.dynamics.desired_gap`, no clamp).

Lanes are relative to the ego's: -1 left, 0 own, +1 right. Positions are the centres along the road
relative to the ego's centre at the decision [m]; speeds in m/s, accelerations in m/s^2.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable

from common.compiled import clip
from common.longitudinal import BrakingLimits, GapKeeping, gap_acceleration, needs_full_braking

OUTCOME = ("at_fault", "min_ttc", "progress", "emergency", "end_speed", "option_speed")
"""What `rollout` returns per command, in its columns' order."""

IDM_ACCELERATION = 3.0
"""The others' IDM maximum acceleration [m/s^2] (highway-env's)."""
IDM_DECELERATION = 5.0
"""Their IDM desired deceleration [m/s^2]."""
IDM_STANDSTILL = 5.0
"""Their IDM jam distance [m]."""
IDM_TIME_GAP = 1.5
"""Their IDM time gap [s]."""
IDM_LIMIT = 6.0
"""Largest acceleration or deceleration an IDM vehicle applies [m/s^2] (highway-env's ACC_MAX)."""
OPTION_RANGE = 60.0
"""How far ahead of the ego's end position the lane beyond a change's target is read [m]."""
NO_TTC = 1e3
"""The TTC reported when nothing closes in [s]."""


class EgoModel(NamedTuple):
    """The ego as the rollout drives it: the adaptive cruise's gap law, emergency braking's limits
    (full braking, the comfort deceleration the cruise brakes at most, the trigger TTC), the set
    speed [m/s], the speed gain [1/s], the largest acceleration [m/s^2], its length and width and
    the lane width [m]."""

    gap: GapKeeping
    braking: BrakingLimits
    set_speed: float
    kp_speed: float
    max_accel: float
    length: float
    width: float
    lane_width: float


@register_jitable
def rollout(
    shifts: np.ndarray,
    durations: np.ndarray,
    speed: float,
    lane: np.ndarray,
    centre: np.ndarray,
    length: np.ndarray,
    velocity: np.ndarray,
    ego: EgoModel,
    steps: int,
    dt: float,
    left: int,
    right: int,
) -> np.ndarray:  # pragma: no cover - compiled; covered through the agent's tests
    """(commands, 6): per command (lane shift `shifts`, lane-change duration `durations` [s]) the
    `OUTCOME`: an at-fault collision (1/0), the smallest TTC [s], the ego's progress [m], emergency
    braking (1/0), the ego's speed at the end [m/s] and, for a change, the speed the lane beyond its
    target offers then (the lane a second change the same way would reach: the nearest vehicle's
    within `OPTION_RANGE` ahead, else the set speed; 0 for STAY or when there is no such lane);
    over `steps` steps of `dt` [s] from the ego at `speed` and the others at (`lane`, `centre`,
    `length`, `velocity`), on a road with `left` and `right` lanes beside the ego's (as far as
    seen). An at-fault collision: the ego reaches a vehicle ahead in a lane it occupies, or any
    vehicle in the lane it moves into; being hit from behind in its own lane is not its fault and
    is not counted."""
    set_speed, kp, max_accel = ego.set_speed, ego.kp_speed, ego.max_accel
    comfort = ego.braking.comfort_deceleration
    ego_length, ego_width, width = ego.length, ego.width, ego.lane_width
    count = lane.shape[0]
    outcome = np.zeros((shifts.shape[0], 6))
    s = np.empty(count)
    v = np.empty(count)
    a = np.empty(count)
    for c in range(shifts.shape[0]):
        shift, duration = shifts[c], durations[c]
        s[:] = centre
        v[:] = velocity
        ego_s, ego_v = 0.0, speed
        min_ttc, at_fault, emergency = NO_TTC, 0.0, 0.0
        for k in range(steps):
            t = k * dt
            changing = shift != 0 and t < duration
            u = min(t / duration, 1.0) if shift != 0 else 0.0
            d = abs(shift) * width * u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
            in_origin = d < (width + ego_width) / 2
            in_target = shift != 0 and d > (width - ego_width) / 2
            command = kp * (set_speed - ego_v)
            braking = False
            for follow in (0, shift):
                if follow == 0 and shift != 0 and not changing:
                    continue
                if follow != 0 and shift == 0:
                    continue
                nearest, gap = -1, 0.0
                for i in range(count):
                    if lane[i] == follow and s[i] > ego_s:
                        here = s[i] - ego_s - (length[i] + ego_length) / 2
                        if nearest < 0 or here < gap:
                            nearest, gap = i, here
                if nearest < 0:
                    continue
                command = min(command, gap_acceleration(ego.gap, ego_v, gap, v[nearest]))
                if needs_full_braking(ego.braking, ego_v, gap, v[nearest], 0.0):
                    braking = True
            command = clip(command, -comfort, max_accel)
            if braking:
                command = -ego.braking.max_deceleration
                emergency = 1.0
            for i in range(count):
                leader_gap, leader_v = 1e9, v[i]
                occupied = (lane[i] == 0 and in_origin) or (lane[i] == shift and in_target)
                if occupied and ego_s > s[i]:
                    leader_gap, leader_v = ego_s - s[i] - (length[i] + ego_length) / 2, ego_v
                for j in range(count):
                    if j != i and lane[j] == lane[i] and s[j] > s[i]:
                        here = s[j] - s[i] - (length[i] + length[j]) / 2
                        if here < leader_gap:
                            leader_gap, leader_v = here, v[j]
                desired_speed = max(v[i], 1.0)
                wanted = IDM_STANDSTILL + max(
                    0.0,
                    v[i] * IDM_TIME_GAP
                    + v[i] * (v[i] - leader_v) / (2 * np.sqrt(IDM_ACCELERATION * IDM_DECELERATION)),
                )
                free = 1.0 - (max(v[i], 0.0) / desired_speed) ** 4
                a[i] = IDM_ACCELERATION * (free - (wanted / max(leader_gap, 0.1)) ** 2)
                a[i] = min(max(a[i], -IDM_LIMIT), IDM_LIMIT)
            ego_v = max(ego_v + command * dt, 0.0)
            ego_s += ego_v * dt
            for i in range(count):
                v[i] = max(v[i] + a[i] * dt, 0.0)
                s[i] += v[i] * dt
            for i in range(count):
                occupied = (lane[i] == 0 and in_origin) or (lane[i] == shift and in_target)
                if not occupied:
                    continue
                ahead = s[i] > ego_s
                gap = abs(s[i] - ego_s) - (length[i] + ego_length) / 2
                if gap <= 0.0:
                    if ahead or lane[i] != 0:
                        at_fault = 1.0
                    continue
                closing = ego_v - v[i] if ahead else (v[i] - ego_v if lane[i] != 0 else 0.0)
                if closing > 0:
                    min_ttc = min(min_ttc, gap / closing)
            if at_fault:
                break
        outcome[c, 0], outcome[c, 1], outcome[c, 2], outcome[c, 3] = at_fault, min_ttc, ego_s, emergency
        outcome[c, 4] = ego_v
        onward = shift + shift
        if shift != 0 and -left <= onward <= right:
            closest, flow = OPTION_RANGE, set_speed
            for i in range(count):
                ahead = s[i] - ego_s
                if lane[i] == onward and 0.0 < ahead < closest:
                    closest, flow = ahead, min(v[i], set_speed)
            outcome[c, 5] = flow
    return outcome
