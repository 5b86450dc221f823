"""Compiled (numba) kernels of the vector road. Two kinds of work: that whose result cannot depend
on float rounding (the collision pairs that could touch, `close_pair_rows`: a filter with a margin,
so any math library will do), and the arithmetic numba computes to numpy's bits: the frame's lane
coordinates, order and neighbour search, the closest lane, and IDM's and the steering controller's
sums, products, divisions, comparisons and float modulo around numpy's transcendental calls, each
in numpy's operation order (numba contracts no multiply-add; `tests/test_sim_backends.py` checks
the bits). numpy's tan, arctan, arcsin, power and dot product stay in numpy: its SVML loops round
differently from libm, which compiled code would call."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

NOT_ZERO = 1e-2
"""highway-env's `utils.not_zero` threshold [same unit as the value]."""
SEPARATION_MARGIN = 1e-6
"""Distance [m] by which two swept rectangles must be apart on one of their axes before the narrow
phase is skipped; float rounding differences with stock's own projections are below 1e-10 m."""


@njit(cache=True, nogil=True, inline="always")
def _half_extent(
    length: float, width: float, cos: float, sin: float, axis_x: float, axis_y: float
) -> float:  # pragma: no cover - compiled; covered through motion.close_pairs
    """Half the extent [m] of a `length` x `width` rectangle, heading (cos, sin), along a unit axis."""
    along = abs(cos * axis_x + sin * axis_y)
    across = abs(-sin * axis_x + cos * axis_y)
    return length / 2 * along + width / 2 * across


@njit(cache=True, nogil=True)
def close_pair_rows(
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    speed: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    diagonal: np.ndarray,
    dt: float,
    broad_margin: float,
    separation_margin: float,
) -> np.ndarray:  # pragma: no cover - compiled; covered through motion.close_pairs
    count = x.shape[0]
    cos = np.cos(heading)
    sin = np.sin(heading)
    pairs = np.empty((max(count * (count - 1) // 2, 1), 2), dtype=np.int64)
    found = 0
    axis_x = np.empty(4)
    axis_y = np.empty(4)
    for a in range(count):
        for b in range(a + 1, count):
            reach = (diagonal[a] + diagonal[b]) / 2 + speed[a] * dt + broad_margin
            if math.sqrt((x[b] - x[a]) ** 2 + (y[b] - y[a]) ** 2) > reach:
                continue
            relative_x = speed[a] * cos[a] - speed[b] * cos[b]
            relative_y = speed[a] * sin[a] - speed[b] * sin[b]
            axis_x[0], axis_y[0] = cos[a], sin[a]
            axis_x[1], axis_y[1] = -sin[a], cos[a]
            axis_x[2], axis_y[2] = cos[b], sin[b]
            axis_x[3], axis_y[3] = -sin[b], cos[b]
            apart = False
            for k in range(4):
                ax, ay = axis_x[k], axis_y[k]
                extent_a = _half_extent(length[a], width[a], cos[a], sin[a], ax, ay)
                extent_b = _half_extent(length[b], width[b], cos[b], sin[b], ax, ay)
                centre_a = x[a] * ax + y[a] * ay
                centre_b = x[b] * ax + y[b] * ay
                sweep = (relative_x * ax + relative_y * ay) * dt
                min_a = centre_a - extent_a + min(sweep, 0.0)
                max_a = centre_a + extent_a + max(sweep, 0.0)
                min_b, max_b = centre_b - extent_b, centre_b + extent_b
                gap = min_b - max_a if min_a < min_b else min_a - max_b
                if gap > separation_margin:
                    apart = True
                    break
            if not apart:
                pairs[found, 0] = a
                pairs[found, 1] = b
                found += 1
    return pairs[:found]


@njit(cache=True, nogil=True)
def _lane_coordinates(
    x: np.ndarray, y: np.ndarray, start: np.ndarray, direction: np.ndarray, lateral: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled; covered through its callers
    """Longitudinal s (n,) [m], the same on every lane, and lateral r (L, n) [m] coordinates of
    objects at (`x`, `y`) [m] on lanes starting at `start` (L, 2), level along the shared unit
    `direction`, with unit `lateral` directions (L, 2); as highway-env's `local_coordinates`
    computes them (exact: every product is by 0 or +-1)."""
    count, lanes = x.shape[0], start.shape[0]
    s = np.empty(count)
    r = np.empty((lanes, count))
    for i in range(count):
        s[i] = (x[i] - start[0, 0]) * direction[0] + (y[i] - start[0, 1]) * direction[1]
        for lane in range(lanes):
            dx, dy = x[i] - start[lane, 0], y[i] - start[lane, 1]
            r[lane, i] = dx * lateral[lane, 0] + dy * lateral[lane, 1]
    return s, r


@njit(cache=True, nogil=True, inline="always")
def _maximum_zero(x: float) -> float:  # pragma: no cover - compiled; covered through closest_lanes
    """`np.maximum(x, 0)`: NaN stays NaN."""
    return x if x >= 0 or x != x else 0.0


@njit(cache=True, nogil=True)
def closest_lanes(
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    start: np.ndarray,
    direction: np.ndarray,
    lateral: np.ndarray,
    length: np.ndarray,
    lane_heading: np.ndarray,
) -> np.ndarray:  # pragma: no cover - compiled; covered through LaneTable.closest
    """Row of each object's closest lane by highway-env's `distance_with_heading` (|r| + the
    distance beyond either end + |heading difference wrapped to [-pi, pi)|), the first on ties
    and the first NaN if any, as numpy's `argmin`: sums, comparisons and a float modulo, each in
    numpy's operation order (the same bits). Lanes as in `lane_order`, headings [rad]."""
    s, r = _lane_coordinates(x, y, start, direction, lateral)
    rows = np.zeros(x.shape[0], dtype=np.int64)
    for i in range(x.shape[0]):
        best = np.inf
        for lane in range(start.shape[0]):
            angle = abs(((heading[i] - lane_heading[lane] + np.pi) % (2 * np.pi)) - np.pi)
            distance = abs(r[lane, i]) + _maximum_zero(s[i] - length[lane]) + _maximum_zero(0 - s[i])
            distance = distance + angle
            if distance != distance:
                rows[i] = lane
                break
            if lane == 0 or distance < best:
                rows[i], best = lane, distance
    return rows


@njit(cache=True, nogil=True)
def lane_order(
    position: np.ndarray,
    start: np.ndarray,
    direction: np.ndarray,
    lateral: np.ndarray,
    length: np.ndarray,
    half_width: np.ndarray,
    vehicle_length: float,
    margin: float,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool, np.ndarray, np.ndarray
]:  # pragma: no cover - compiled; covered through TrafficFrame
    """`TrafficFrame`'s lane coordinates and search tables of objects at `position` (n, 2) [m] on
    parallel straight lanes (`start` (L, 2) [m], the shared unit `direction`, unit `lateral` (L, 2),
    `length` and `half_width` [m]): s (n,) and r (L, n) [m] (`_lane_coordinates`); the order by
    s (ties by row), the sorted s and whether two tie; per lane and sorted position p, the first
    position >= p (n if none) and the last position < p (-1 if none) of an object on the lane as
    `Road.neighbour_vehicles` counts it (highway-env's `on_lane` with a lateral `margin` [m],
    `vehicle_length` [m] beyond both ends), exact comparisons all."""
    count, lanes = position.shape[0], start.shape[0]
    s, r = _lane_coordinates(position[:, 0], position[:, 1], start, direction, lateral)
    order = np.argsort(s, kind="mergesort")
    sorted_s = s[order]
    tied = False
    for p in range(1, count):
        tied = tied or sorted_s[p] == sorted_s[p - 1]
    next_on = np.empty((lanes, count + 1), dtype=np.int64)
    last_before = np.empty((lanes, count + 1), dtype=np.int64)
    on = np.empty(count, dtype=np.bool_)
    for lane in range(lanes):
        low, high = -vehicle_length, length[lane] + vehicle_length
        reach = half_width[lane] + margin
        for p in range(count):
            i = order[p]
            on[p] = low <= s[i] and s[i] < high and abs(r[lane, i]) <= reach
        following = count
        next_on[lane, count] = count
        for p in range(count - 1, -1, -1):
            if on[p]:
                following = p
            next_on[lane, p] = following
        preceding = -1
        last_before[lane, 0] = -1
        for p in range(count):
            if on[p]:
                preceding = p
            last_before[lane, p + 1] = preceding
    return s, r, order, sorted_s, tied, next_on, last_before


@njit(cache=True, nogil=True)
def neighbour_rows(
    me: np.ndarray,
    lane_rows: np.ndarray,
    s: np.ndarray,
    order: np.ndarray,
    sorted_s: np.ndarray,
    next_on: np.ndarray,
    last_before: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled; covered through TrafficFrame
    """Rows of the (front, rear) of the objects in rows `me`, each on its lane of `lane_rows`, from
    `lane_order`'s tables of a frame without ties in s: front the first object on the lane at
    s_v >= s other than itself, rear the last at s_v < s (-1 for none)."""
    count = order.shape[0]
    front = np.empty(me.shape[0], dtype=np.int64)
    rear = np.empty(me.shape[0], dtype=np.int64)
    for k in range(me.shape[0]):
        lane = lane_rows[k]
        start = np.searchsorted(sorted_s, s[me[k]], side="left")
        ahead = next_on[lane, start]
        if ahead < count and order[ahead] == me[k]:
            ahead = next_on[lane, min(ahead + 1, count)]
        behind = last_before[lane, start]
        front[k] = order[ahead] if ahead < count else -1
        rear[k] = order[behind] if behind >= 0 else -1
    return front, rear


@njit(cache=True, nogil=True, inline="always")
def _maximum(a: float, b: float) -> float:  # pragma: no cover - compiled
    """`np.maximum(a, b)`: NaN in `a` stays."""
    return a if a >= b or a != a else b


@njit(cache=True, nogil=True, inline="always")
def _minimum(a: float, b: float) -> float:  # pragma: no cover - compiled
    """`np.minimum(a, b)`: NaN in `a` stays."""
    return a if a <= b or a != a else b


@njit(cache=True, nogil=True, inline="always")
def _not_zero(x: float) -> float:  # pragma: no cover - compiled
    """highway-env's `utils.not_zero`: +-`NOT_ZERO` for values closer to 0 (NaN gives -NOT_ZERO)."""
    return x if abs(x) > NOT_ZERO else (NOT_ZERO if x >= 0 else -NOT_ZERO)


@njit(cache=True, nogil=True)
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
        desired = target if limit != limit else _minimum(_maximum(target, 0.0), limit)
        base[i] = _maximum(speed[e], 0.0) / abs(_not_zero(desired))
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


@njit(cache=True, nogil=True)
def idm_gap_ratios(
    closing: np.ndarray,
    gap: np.ndarray,
    led_speed: np.ndarray,
    distance_wanted: np.ndarray,
    valid: np.ndarray,
    led: np.ndarray,
    time_wanted: float,
    braking_term: float,
) -> np.ndarray:  # pragma: no cover - compiled; covered through TrafficFrame.idm
    """Desired gap / gap of each led row of `idm_inputs`: the desired gap d0 + v T + v dv /
    `braking_term` (2 sqrt(a b)), in highway-env's operation order, `distance_wanted` d0 [m] by
    the evaluating row."""
    ratio = np.empty(gap.shape[0])
    j = 0
    for i in range(valid.shape[0]):
        if led[i]:
            v = led_speed[j]
            desired = distance_wanted[valid[i]] + v * time_wanted + v * closing[j] / braking_term
            ratio[j] = desired / _not_zero(gap[j])
            j += 1
    return ratio


@njit(cache=True, nogil=True)
def idm_accelerations(
    rows: int, valid: np.ndarray, free_power: np.ndarray, led: np.ndarray, gap_power: np.ndarray, a_max: float
) -> np.ndarray:  # pragma: no cover - compiled; covered through TrafficFrame.idm
    """IDM's a_max (1 - (v / v0)^delta) - a_max (s* / s)^2 per evaluating row from the powers numpy
    computed, 0 for rows without a valid ego."""
    acceleration = np.zeros(rows)
    j = 0
    for i in range(valid.shape[0]):
        a = a_max * (1 - free_power[i])
        if led[i]:
            a = a - a_max * gap_power[j]
            j += 1
        acceleration[valid[i]] = a
    return acceleration


@njit(cache=True, nogil=True, inline="always")
def _clip(x: float, bound: float) -> float:  # pragma: no cover - compiled
    """`lanes.clip`: np.minimum(np.maximum(x, -bound), bound)."""
    return _minimum(_maximum(x, -bound), bound)


@njit(cache=True, nogil=True)
def lateral_command_sines(
    r_target: np.ndarray, speed: np.ndarray, kp_lateral: float
) -> np.ndarray:  # pragma: no cover - compiled; covered through VectorRoad
    """The sine of `IDMVehicle.steering_control`'s heading command, -kp r / v clipped to [-1, 1],
    per driver at lateral offset `r_target` [m] from its target lane's centre and `speed` [m/s]."""
    sine = np.empty(r_target.shape[0])
    for i in range(r_target.shape[0]):
        sine[i] = _clip(-kp_lateral * r_target[i] / _not_zero(speed[i]), 1.0)
    return sine


@njit(cache=True, nogil=True)
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
        rate = kp_heading * (((reference - heading[i] + np.pi) % (2 * np.pi)) - np.pi)
        sine[i] = _clip(length[i] / 2 / _not_zero(speed[i]) * rate, 1.0)
    return sine


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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
