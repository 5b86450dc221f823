"""The ego's control of one world, compiled (numba) for a batch of worlds to call per world: the
maneuver's warped quintic reference, the adaptive cruise's leaders, the lateral PID, the cruise's
speed PI and gap law, and emergency braking, each following its per-world class
(`controllers.maneuver`, `leaders`, `lateral`, `cruise`, `emergency`) operation by operation.

The quintic itself is the per-world code compiled (`controllers.reference`: closed-form
coefficients, Horner's rule); sums, products, quotients and `math`'s libm calls (asin, atan, tan,
sin, sqrt) give the per-world code's bits in numba. The kinematic plant only (no dynamic-bicycle
inversion): a batch of another plant is refused before it gets here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from controllers.bicycle import LENGTH
from controllers.cruise import AdaptiveCruise
from controllers.emergency import EmergencyBraking
from controllers.lateral import FULL_BANDWIDTH_SPEED, MAX_COURSE, MIN_SPEED
from controllers.leaders import LEAVING_M, SIDE_MARGIN_M
from controllers.reference import quintic_at, quintic_coefficients, quintic_peak_speed

coefficients = njit(cache=True, nogil=True)(quintic_coefficients)
"""`controllers.reference.quintic_coefficients`, compiled."""
_at = njit(cache=True, nogil=True)(quintic_at)
peak_speed = njit(cache=True, nogil=True)(quintic_peak_speed)
"""`controllers.reference.quintic_peak_speed`, compiled."""

SIN_MAX_COURSE = math.sin(MAX_COURSE)
"""The lateral PID's course limit as a share of the speed (`LateralPID.update`)."""
KP_GAP, KP_CLOSING = AdaptiveCruise.KP_GAP, AdaptiveCruise.KP_CLOSING
STOP_MARGIN_M = EmergencyBraking.STOP_MARGIN_M
BRAKING_SEEN_MPS2 = EmergencyBraking.BRAKING_SEEN_MPS2


@njit(cache=True, nogil=True)
def warped_sample(
    c: np.ndarray,
    t0: float,
    duration: float,
    d1: float,
    anchor: float,
    profile_anchor: float,
    rate: float,
    t: float,
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """`WarpedProfile.sample(t)` of the quintic `c` (t0, duration [s], end d1 [m]) on the clock
    (anchor, profile_anchor [s], rate): (d [m], d_dot [m/s], d_ddot [m/s^2])."""
    profile_time = profile_anchor + (t - anchor) * rate
    if profile_time - t0 >= duration:
        d, d_dot, d_ddot = d1, 0.0, 0.0
    else:
        tau = profile_time - t0
        d, d_dot, d_ddot = _at(c[0], c[1], c[2], c[3], c[4], c[5], tau if tau > 0.0 else 0.0)
    return d, d_dot * rate, d_ddot * (rate * rate)


@njit(cache=True, nogil=True)
def passed_before_reached(
    row: int,
    s: np.ndarray,
    d: np.ndarray,
    speed: np.ndarray,
    heading: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    extent: np.ndarray,
    lane_heading: float,
) -> bool:  # pragma: no cover - compiled
    """`controllers.leaders.passed_before_reached` of the vehicle in `row` (row 0 the ego)."""
    rel_s, closing = s[row] - s[0], speed[0] - speed[row]
    clear_s = (rel_s + (length[0] + length[row]) / 2) / closing
    towards = math.copysign(1.0, d[0] - d[row])
    lateral = towards * speed[row] * math.sin(heading[row] - lane_heading)
    apart = abs(d[row] - d[0]) - width[0] / 2 - SIDE_MARGIN_M
    if apart - extent[row] / 2 <= 0:
        return False
    side_gap = apart - width[row] / 2
    return lateral <= 0 or clear_s < side_gap / lateral


@njit(cache=True, nogil=True)
def leaders_of(
    lanes: np.ndarray,
    n: int,
    s: np.ndarray,
    d: np.ndarray,
    speed: np.ndarray,
    heading: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    extent: np.ndarray,
    offsets: np.ndarray,
    lane_width: float,
    lane_heading: float,
    gaps: np.ndarray,
    speeds: np.ndarray,
    rows: np.ndarray,
) -> int:  # pragma: no cover - compiled
    """`controllers.leaders.leaders(world, lanes)` of one world's `n` vehicles (row 0 the ego;
    `extent`: each one's turned footprint across the road [m]): writes each leader's gap [m],
    speed [m/s] and row in order and returns how many."""
    found = 0
    candidates = np.empty(n, dtype=np.int64)
    for lane in lanes:
        m = 0
        for row in range(1, n):
            rel = s[row] - s[0]
            offset = abs(d[row] - offsets[lane])
            if not (offset < (lane_width + extent[row]) / 2 and rel > 0):
                continue
            if offset > LEAVING_M and speed[row] < speed[0]:
                if passed_before_reached(row, s, d, speed, heading, length, width, extent, lane_heading):
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


@njit(cache=True, nogil=True, inline="always")
def clip(x: float, low: float, high: float) -> float:  # pragma: no cover - compiled
    """`records.clip`: numpy's rule, a NaN stays NaN, a tie keeps the bound."""
    x = x if x != x or x > low else low
    return x if x != x or x < high else high


@njit(cache=True, nogil=True)
def pid_update(
    state: np.ndarray,
    kp: float,
    ki: float,
    low: float,
    high: float,
    error: float,
    dt: float,
    feedforward: float,
) -> float:  # pragma: no cover - compiled
    """`controllers.pid.PID.update` (kd 0, no rate limit) on `state` = [integral, output, has
    output]: the output, clamp anti-windup, limits (low, high)."""
    proportional_part = kp * error + 0.0 * 0.0 + feedforward
    candidate = state[0] + ki * error * dt
    unclamped = proportional_part + candidate
    saturated_high = unclamped > high and error > 0
    saturated_low = unclamped < low and error < 0
    if not (saturated_high or saturated_low):
        state[0] = candidate
    output = clip(proportional_part + state[0], low, high)
    if state[2] != 0.0:
        step = math.inf * dt
        output = clip(output, state[1] - step, state[1] + step)
    state[1], state[2] = output, 1.0
    return output


@njit(cache=True, nogil=True)
def lateral_steering(
    state: np.ndarray,
    gains: np.ndarray,
    d: float,
    heading: float,
    speed: float,
    curvature: float,
    d_ref: float,
    d_dot_ref: float,
    d_ddot_ref: float,
    dt: float,
) -> float:  # pragma: no cover - compiled
    """`controllers.lateral.LateralPID.update` on the kinematic bicycle: the steering [rad] for
    the ego at lateral offset `d` [m], `heading` to the lane [rad], `speed` [m/s], on a lane of
    `curvature` [1/m]; `gains` = (kp_lateral, ki_lateral, kp_heading, steering_rate,
    max_steering), `state` = [integral, output, has output, last steering]."""
    v = max(speed, MIN_SPEED)
    sigma = min(1.0, max(v, MIN_SPEED) / FULL_BANDWIDTH_SPEED)
    if sigma == 1.0:
        kp, ki, kp_heading = gains[0], gains[1], gains[2]
    else:
        kp, ki, kp_heading = gains[0] * sigma, gains[1] * (sigma * sigma), gains[2] * sigma
    high = v * SIN_MAX_COURSE
    lateral_speed = pid_update(state, kp, ki, -high, high, d_ref - d, dt, d_dot_ref)
    course = math.asin(clip(lateral_speed / v, -1.0, 1.0))
    road_rate = curvature * v / (1 - curvature * d)
    feedforward_rate = d_ddot_ref / v + road_rate
    slip = math.asin(clip(LENGTH / 2 * feedforward_rate / v, -0.5, 0.5))
    heading_error = course - slip - heading
    stoppable = math.sqrt(v * gains[3] / LENGTH * abs(heading_error))
    yaw_rate = feedforward_rate + math.copysign(
        min(kp_heading * abs(heading_error), stoppable), heading_error
    )
    beta = math.asin(clip(LENGTH / 2 * yaw_rate / v, -0.7, 0.7))
    step = gains[3] * dt
    last = state[3]
    steering = clip(math.atan(2 * math.tan(beta)), max(-gains[4], last - step), min(gains[4], last + step))
    state[3] = steering
    return steering


@njit(cache=True, nogil=True)
def cruise_acceleration(
    state: np.ndarray,
    gains: np.ndarray,
    speed: float,
    set_speed: float,
    gaps: np.ndarray,
    speeds: np.ndarray,
    leaders: int,
    dt: float,
) -> float:  # pragma: no cover - compiled
    """`controllers.cruise.AdaptiveCruise.update`: the acceleration command [m/s^2]; `gains` =
    (kp_speed, ki_speed, comfort deceleration, max acceleration, time gap, standstill gap),
    `state` the speed PI's [integral, output, has output]."""
    comfort, top = gains[2], gains[3]
    command = pid_update(state, gains[0], gains[1], -comfort, top, set_speed - speed, dt, 0.0)
    for k in range(leaders):
        desired_gap = gains[5] + gains[4] * speed
        closing = speed - speeds[k]
        candidate = KP_GAP * (gaps[k] - desired_gap) - KP_CLOSING * closing
        if candidate < command:
            command = candidate
    return clip(command, -comfort, top)


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
    limits: np.ndarray,
    dt: float,
) -> float:  # pragma: no cover - compiled
    """`controllers.emergency.EmergencyBraking.apply`: `acceleration` [m/s^2], or full braking
    while an emergency lasts, never reversing. Per vehicle row, `seen` holds 1 where it was a
    leader last tick (its speed then in `seen_speed`) and 2 where it was one the tick before too
    (its slowing then in `seen_slowing` [m/s^2]); `flags` = [active, activations]; `limits` =
    (max deceleration, comfort deceleration, trigger TTC)."""
    braking = np.zeros(leaders)
    rates = np.zeros(leaders)
    rated = np.zeros(leaders, dtype=np.bool_)
    for k in range(leaders):
        row = rows[k]
        if seen[row] >= 1:
            rate = (seen_speed[row] - speeds[k]) / dt
            rates[k], rated[k] = rate, True
            slowing = seen_slowing[row] if seen[row] == 2 else 0.0
            braking[k] = slowing if slowing < rate else rate
    seen[:] = 0
    for k in range(leaders):
        seen_speed[rows[k]] = speeds[k]
        seen[rows[k]] = 1
    for k in range(leaders):
        if rated[k]:
            seen_slowing[rows[k]] = rates[k]
            seen[rows[k]] = 2
    if flags[0] != 0:
        closing_in = False
        for k in range(leaders):
            closing_in = closing_in or speed > speeds[k]
        flags[0] = 1 if closing_in else 0
    else:
        for k in range(leaders):
            closing = speed - speeds[k]
            if closing <= 0:
                continue
            room = max(gaps[k] - STOP_MARGIN_M, 0.01)
            slowing = braking[k] if rated[k] else 0.0
            stopping = slowing > BRAKING_SEEN_MPS2
            stops_in = speeds[k] * speeds[k] / (2 * slowing) if stopping else 0.0
            if (
                closing * closing / (2 * room) > limits[1]
                or gaps[k] / closing < limits[2]
                or (stopping and speed * speed / (2 * (room + stops_in)) > limits[1])
            ):
                flags[0] = 1
                flags[1] += 1
                break
    commanded = -limits[0] if flags[0] != 0 else acceleration
    floor = -max(speed, 0.0) / dt
    return floor if floor > commanded else commanded
