"""Compiled (numba) arithmetic of the vector road's vehicles: IDM, the steering controller,
`clip_actions` and the kinematic bicycle's update. Each kernel computes the sums, products, divisions,
comparisons and float modulo in numpy's operation order, and numba contracts no multiply-add, so the
bits are numpy's (`tests/test_sim_backends.py` checks them). The transcendental functions (tan,
arctan, arcsin, cos, sin, power) and the dot products stay in numpy between the kernels: numpy's SVML
loops round differently from the libm compiled code would call, and highway-env computes with numpy."""

from __future__ import annotations

import numpy as np
from highway_env.vehicle.behavior import IDMVehicle
from numba import njit

from common.compiled import Kernel
from stack.sim.vector.geometry_kernels import maximum, minimum, wrap_to_pi
from stack.sim.vector.lanes import clip

NOT_ZERO = 1e-2
"""highway-env's `utils.not_zero` threshold [same unit as the value]."""


@njit(cache=True, nogil=True, inline="always")
def _not_zero(x: float) -> float:  # pragma: no cover - compiled
    """highway-env's `utils.not_zero`: +-`NOT_ZERO` for values closer to 0 (NaN gives -NOT_ZERO)."""
    return x if abs(x) > NOT_ZERO else (NOT_ZERO if x >= 0 else -NOT_ZERO)


@Kernel
def idm_inputs(
    ego: np.ndarray,
    front: np.ndarray,
    is_vehicle: np.ndarray,
    speed: np.ndarray,
    target_speed: np.ndarray,
    speed_limit: np.ndarray,
    s: np.ndarray,
    velocity: np.ndarray,
    direction: np.ndarray,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]:  # pragma: no cover - compiled; covered through TrafficFrame.idm
    """The rounding-exact parts of IDM for evaluating rows `ego` behind rows `front` (-1: none):
    the valid rows (an ego that is a vehicle); for each, the free-road base max(v, 0) / |desired
    speed| (the target speed clipped to [0, the lane's `speed_limit`], NaN: none), whether it is
    led; for each led one, the relative velocity and the ego's heading direction (for the
    closing speed's dot product, which numpy rounds its own way), the gap in s [m], its speed."""
    valid = np.empty(ego.shape[0], dtype=np.int64)
    count = 0
    for k in range(ego.shape[0]):
        if ego[k] >= 0 and is_vehicle[ego[k]]:
            valid[count] = k
            count += 1
    valid = valid[:count]
    base = np.empty(count)
    led = np.zeros(count, dtype=np.bool_)
    for i in range(count):
        e = ego[valid[i]]
        limit, target = speed_limit[e], target_speed[e]
        desired = target if limit != limit else minimum(maximum(target, 0.0), limit)
        base[i] = maximum(speed[e], 0.0) / abs(_not_zero(desired))
        led[i] = front[valid[i]] >= 0
    led_count = int(led.sum())
    relative, heading = np.empty((led_count, 2)), np.empty((led_count, 2))
    gap, led_speed = np.empty(led_count), np.empty(led_count)
    j = 0
    for i in range(count):
        if led[i]:
            e, f = ego[valid[i]], front[valid[i]]
            for axis in range(2):
                relative[j, axis] = velocity[e, axis] - velocity[f, axis]
                heading[j, axis] = direction[e, axis]
            gap[j], led_speed[j] = s[f] - s[e], speed[e]
            j += 1
    return valid, base, led, relative, heading, gap, led_speed


@njit(cache=True, nogil=True, inline="always")
def desired_gap(
    distance_wanted: float, time_wanted: float, braking_term: float, speed: float, closing: float
) -> float:  # pragma: no cover - compiled
    """IDM's desired gap s* = d0 + v T + v dv / (2 sqrt(a b)) [m] as highway-env's `desired_gap`
    computes it (its operation order): jam distance `distance_wanted` d0 [m], time gap
    `time_wanted` T [s], `braking_term` 2 sqrt(a b) [m/s^2], `speed` v and `closing` speed dv [m/s]."""
    return distance_wanted + speed * time_wanted + speed * closing / braking_term


@njit(cache=True, nogil=True, inline="always")
def mobil_accepts(
    new_rear_a: float,
    new_rear_pred_a: float,
    self_pred_a: float,
    self_a: float,
    own_rear_a: float,
    own_rear_pred_a: float,
    politeness: float,
    min_gain: float,
    max_braking_imposed: float,
) -> bool:  # pragma: no cover - compiled
    """`IDMVehicle.mobil` for a driver without a route: the change is safe (the new follower brakes
    no harder than `max_braking_imposed` [m/s^2]) and worth it (the driver's gain plus `politeness`
    times its followers' is at least `min_gain` [m/s^2]), from the six IDM accelerations [m/s^2]
    (new rear behind new front, and behind the driver; the driver behind the new front, and behind
    its own; its own rear behind it, and behind its own front), in highway-env's operation order."""
    if new_rear_pred_a < -max_braking_imposed:
        return False
    gain = self_pred_a - self_a + politeness * (new_rear_pred_a - new_rear_a + own_rear_pred_a - own_rear_a)
    return not gain < min_gain


@Kernel
def mobil_verdicts(
    accelerations: np.ndarray,
    decider: np.ndarray,
    politeness: np.ndarray,
    min_gain: np.ndarray,
    max_braking_imposed: np.ndarray,
) -> np.ndarray:  # pragma: no cover - compiled; covered through VectorRoad
    """`mobil_accepts` per candidate change: `accelerations` (6, candidates) in its order, the
    MOBIL parameters of each candidate's `decider` (its row in those arrays)."""
    accept = np.empty(accelerations.shape[1], dtype=np.bool_)
    for k in range(accelerations.shape[1]):
        a, d = accelerations[:, k], decider[k]
        accept[k] = mobil_accepts(
            a[0], a[1], a[2], a[3], a[4], a[5], politeness[d], min_gain[d], max_braking_imposed[d]
        )
    return accept


@Kernel
def idm_gap_ratios(
    closing: np.ndarray,
    gap: np.ndarray,
    led_speed: np.ndarray,
    valid: np.ndarray,
    led: np.ndarray,
    evaluator: np.ndarray,
    distance_wanted: np.ndarray,
    time_wanted: np.ndarray,
    braking_term: np.ndarray,
) -> np.ndarray:  # pragma: no cover - compiled; covered through TrafficFrame.idm
    """Desired gap / gap of each led row of `idm_inputs`: `desired_gap` with the jam distance
    `distance_wanted` d0 [m], time gap `time_wanted` [s] and `braking_term` 2 sqrt(a b) [m/s^2] of
    each pair's `evaluator` (its row in those arrays)."""
    ratio = np.empty(gap.shape[0])
    j = 0
    for i in range(valid.shape[0]):
        if led[i]:
            row = evaluator[valid[i]]
            desired = desired_gap(
                distance_wanted[row], time_wanted[row], braking_term[row], led_speed[j], closing[j]
            )
            ratio[j] = desired / _not_zero(gap[j])
            j += 1
    return ratio


@Kernel
def idm_accelerations(
    rows: int,
    valid: np.ndarray,
    free_power: np.ndarray,
    led: np.ndarray,
    gap_power: np.ndarray,
    evaluator: np.ndarray,
    a_max: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled; covered through TrafficFrame.idm
    """IDM's a_max (1 - (v / v0)^delta) - a_max (s* / s)^2 per evaluating row from the powers numpy
    computed, `a_max` [m/s^2] of each pair's `evaluator`, 0 for rows without a valid ego; and its
    free-road term a_max (1 - (v / v0)^delta) [m/s^2] alone (what IDM gives behind no leader)."""
    acceleration = np.zeros(rows)
    free_road = np.zeros(rows)
    j = 0
    for i in range(valid.shape[0]):
        a_row = a_max[evaluator[valid[i]]]
        a = a_row * (1 - free_power[i])
        free_road[valid[i]] = a
        if led[i]:
            a = a - a_row * gap_power[j]
            j += 1
        acceleration[valid[i]] = a
    return acceleration, free_road


@njit(cache=True, nogil=True, inline="always")
def _clip(x: float, bound: float) -> float:  # pragma: no cover - compiled
    """`lanes.clip`: np.minimum(np.maximum(x, -bound), bound)."""
    return minimum(maximum(x, -bound), bound)


@Kernel
def lateral_command_sines(
    r_target: np.ndarray, speed: np.ndarray, kp_lateral: float
) -> np.ndarray:  # pragma: no cover - compiled; covered through VectorRoad
    """The sine of `IDMVehicle.steering_control`'s heading command, -kp r / v clipped to [-1, 1],
    per driver at lateral offset `r_target` [m] from its target lane's centre and `speed` [m/s]."""
    sine = np.empty(r_target.shape[0])
    for i in range(r_target.shape[0]):
        sine[i] = _clip(-kp_lateral * r_target[i] / _not_zero(speed[i]), 1.0)
    return sine


@Kernel
def slip_sines(
    heading_command: np.ndarray,
    lane_heading: np.ndarray,
    heading: np.ndarray,
    length: np.ndarray,
    speed: np.ndarray,
    kp_heading: float,
) -> np.ndarray:  # pragma: no cover - compiled; covered through VectorRoad
    """The sine of `steering_control`'s slip angle per driver, from its heading command [rad]: the
    heading rate kp (lane heading + command clipped to +-pi/4 - heading, wrapped to [-pi, pi)) times
    L / 2 / v, clipped to [-1, 1]; in highway-env's operation order."""
    sine = np.empty(heading.shape[0])
    for i in range(heading.shape[0]):
        reference = lane_heading[i] + _clip(heading_command[i], np.pi / 4)
        rate = kp_heading * wrap_to_pi(reference - heading[i])
        sine[i] = _clip(length[i] / 2 / _not_zero(speed[i]) * rate, 1.0)
    return sine


@Kernel
def clipped_actions(
    speed: np.ndarray,
    max_speed: np.ndarray,
    min_speed: np.ndarray,
    steering: np.ndarray,
    acceleration: np.ndarray,
    crashed: np.ndarray,
    stops: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled; covered through motion.move
    """Steering [rad] and acceleration [m/s^2] as `Vehicle.clip_actions` leaves them: a crashed
    vehicle brakes to a stop, straight; one that `stops` (`TrafficVehicle`) brakes no harder than
    to a standstill within `dt` [s]; none accelerates beyond its speed range."""
    count = speed.shape[0]
    clipped_steering, clipped_acceleration = steering.copy(), acceleration.copy()
    for i in range(count):
        a = acceleration[i]
        if crashed[i]:
            clipped_steering[i], a = 0.0, -1.0 * speed[i]
        elif stops[i]:
            standstill = -speed[i] / dt
            if standstill > a:
                a = standstill
        if speed[i] > max_speed[i]:
            slow_down = 1.0 * (max_speed[i] - speed[i])
            if slow_down < a:
                a = slow_down
        elif speed[i] < min_speed[i]:
            speed_up = 1.0 * (min_speed[i] - speed[i])
            if speed_up > a:
                a = speed_up
        clipped_acceleration[i] = a
    return clipped_steering, clipped_acceleration


@Kernel
def integrated(
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    speed: np.ndarray,
    acceleration: np.ndarray,
    length: np.ndarray,
    course_cos: np.ndarray,
    course_sin: np.ndarray,
    slip_sin: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled; covered through motion.move
    """`Vehicle.step`'s kinematic bicycle over `dt` [s] from the cosine and sine of each course
    (heading + slip) and the slip's sine, which numpy computes: moves (x, y) [m] in place, returns
    the new headings [rad] and speeds [m/s]; in highway-env's operation order."""
    new_heading, new_speed = np.empty(x.shape[0]), np.empty(x.shape[0])
    for i in range(x.shape[0]):
        x[i] += speed[i] * course_cos[i] * dt
        y[i] += speed[i] * course_sin[i] * dt
        new_heading[i] = heading[i] + speed[i] * slip_sin[i] / (length[i] / 2) * dt
        new_speed[i] = speed[i] + acceleration[i] * dt
    return new_heading, new_speed


def steering_angles(
    r_target: np.ndarray, lane_heading: np.ndarray, heading: np.ndarray, length: np.ndarray, speed: np.ndarray
) -> np.ndarray:
    """`IDMVehicle.steering_control`'s steering [rad] per driver at lateral offset `r_target` [m]
    from its target lane's centre, whose heading is `lane_heading` [rad] (straight lanes), heading
    `heading` [rad], of `length` [m] at `speed` [m/s]: the compiled kernels around numpy's arcsin,
    tan and arctan, clipped to `MAX_STEERING_ANGLE`."""
    heading_command = np.arcsin(lateral_command_sines(r_target, speed, IDMVehicle.KP_LATERAL))
    slip = np.arcsin(slip_sines(heading_command, lane_heading, heading, length, speed, IDMVehicle.KP_HEADING))
    return clip(np.arctan(2 * np.tan(slip)), IDMVehicle.MAX_STEERING_ANGLE)


def bicycle_step(
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    speed: np.ndarray,
    steering: np.ndarray,
    acceleration: np.ndarray,
    length: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """`Vehicle.step`'s kinematic bicycle over `dt` [s] for clipped `steering` [rad] and
    `acceleration` [m/s^2]: moves (x, y) [m] in place, returns the new headings [rad] and speeds
    [m/s]; numpy's arctan, tan, cos and sin around the compiled update."""
    beta = np.arctan(1 / 2 * np.tan(steering))
    course = heading + beta
    return integrated(
        x, y, heading, speed, acceleration, length, np.cos(course), np.sin(course), np.sin(beta), dt
    )
