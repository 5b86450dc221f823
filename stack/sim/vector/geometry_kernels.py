"""Compiled (numba) kernels of the vector road's geometry: the collision pairs that could touch
(`close_pair_rows`: a filter with a margin, so any math library will do), and the frame's lane
coordinates, order and neighbour search and the closest lane (sums, products by 0 or +-1, the float
modulo and comparisons, in numpy's operation order: numpy's bits). The vehicles' behaviour and
motion are in `stack.sim.vector.dynamics`."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from common.compiled import Kernel

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


@njit(cache=True, nogil=True, inline="always")
def within_reach(
    a: int,
    b: int,
    x: np.ndarray,
    y: np.ndarray,
    speed: np.ndarray,
    diagonal: np.ndarray,
    dt: float,
    broad_margin: float,
) -> bool:  # pragma: no cover - compiled; covered through motion.close_pairs
    """highway-env's spherical pre-check of rows `a` and `b` over `dt` [s], with `broad_margin` [m].
    Callers looping over pairs test it before `could_touch`: a call with a dozen arrays costs
    their reference counts (~80 ns), the test itself ~2 ns, and most pairs end here."""
    reach = (diagonal[a] + diagonal[b]) / 2 + speed[a] * dt + broad_margin
    return math.sqrt((x[b] - x[a]) ** 2 + (y[b] - y[a]) ** 2) <= reach


@njit(cache=True, nogil=True)
def could_touch(
    a: int,
    b: int,
    x: np.ndarray,
    y: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    speed: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    diagonal: np.ndarray,
    dt: float,
    broad_margin: float,
    separation_margin: float,
) -> bool:  # pragma: no cover - compiled; covered through motion.close_pairs
    """Whether rows `a` and `b` pass highway-env's spherical pre-check over `dt` [s] (with
    `broad_margin` [m]) and their rectangles, `a`'s swept by the relative displacement, are not
    apart by `separation_margin` [m] along one of their own axes (headings by cos and sin)."""
    if not within_reach(a, b, x, y, speed, diagonal, dt, broad_margin):
        return False
    relative_x = speed[a] * cos[a] - speed[b] * cos[b]
    relative_y = speed[a] * sin[a] - speed[b] * sin[b]
    for k in range(4):
        owner = a if k < 2 else b
        if k % 2 == 0:
            ax, ay = cos[owner], sin[owner]
        else:
            ax, ay = -sin[owner], cos[owner]
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
            return False
    return True


@Kernel
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
    """The pairs (a, b), a < b, by a then b, that `could_touch`."""
    count = x.shape[0]
    cos = np.cos(heading)
    sin = np.sin(heading)
    pairs = np.empty((max(count * (count - 1) // 2, 1), 2), dtype=np.int64)
    found = 0
    for a in range(count):
        for b in range(a + 1, count):
            if within_reach(a, b, x, y, speed, diagonal, dt, broad_margin) and could_touch(
                a, b, x, y, cos, sin, speed, length, width, diagonal, dt, broad_margin, separation_margin
            ):
                pairs[found, 0] = a
                pairs[found, 1] = b
                found += 1
    return pairs[:found]


@njit(cache=True, nogil=True)
def lane_coordinates(
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
def maximum(a: float, b: float) -> float:  # pragma: no cover - compiled
    """`np.maximum(a, b)`: NaN in `a` stays."""
    return a if a >= b or a != a else b


@njit(cache=True, nogil=True, inline="always")
def minimum(a: float, b: float) -> float:  # pragma: no cover - compiled
    """`np.minimum(a, b)`: NaN in `a` stays."""
    return a if a <= b or a != a else b


@njit(cache=True, nogil=True, inline="always")
def counted_on_lane(
    s: float, r: float, length: float, half_width: float, vehicle_length: float, margin: float
) -> bool:  # pragma: no cover - compiled
    """Whether an object at `s` along and `r` across a lane of `length` and `half_width` [m] is on it
    as `Road.neighbour_vehicles` counts it: highway-env's `on_lane` with a lateral `margin` [m],
    `vehicle_length` [m] beyond both ends."""
    return -vehicle_length <= s and s < length + vehicle_length and abs(r) <= half_width + margin


@njit(cache=True, nogil=True, inline="always")
def wrap_to_pi(angle: float) -> float:  # pragma: no cover - compiled
    """highway-env's `utils.wrap_to_pi` [rad]: ((angle + pi) mod 2 pi) - pi, numpy's float modulo."""
    return ((angle + np.pi) % (2 * np.pi)) - np.pi


@Kernel
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
    s, r = lane_coordinates(x, y, start, direction, lateral)
    rows = np.zeros(x.shape[0], dtype=np.int64)
    for i in range(x.shape[0]):
        best = np.inf
        for lane in range(start.shape[0]):
            angle = abs(wrap_to_pi(heading[i] - lane_heading[lane]))
            distance = abs(r[lane, i]) + maximum(s[i] - length[lane], 0.0) + maximum(0 - s[i], 0.0)
            distance = distance + angle
            if distance != distance:
                rows[i] = lane
                break
            if lane == 0 or distance < best:
                rows[i], best = lane, distance
    return rows


@Kernel
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
    `length` and `half_width` [m]): s (n,) and r (L, n) [m] (`lane_coordinates`); the order by
    s (ties by row), the sorted s and whether two tie; per lane and sorted position p, the first
    position >= p (n if none) and the last position < p (-1 if none) of an object on the lane as
    `Road.neighbour_vehicles` counts it (highway-env's `on_lane` with a lateral `margin` [m],
    `vehicle_length` [m] beyond both ends), exact comparisons all."""
    count, lanes = position.shape[0], start.shape[0]
    s, r = lane_coordinates(position[:, 0], position[:, 1], start, direction, lateral)
    order = np.argsort(s, kind="mergesort")
    sorted_s = s[order]
    tied = False
    for p in range(1, count):
        tied = tied or sorted_s[p] == sorted_s[p - 1]
    next_on = np.empty((lanes, count + 1), dtype=np.int64)
    last_before = np.empty((lanes, count + 1), dtype=np.int64)
    on = np.empty(count, dtype=np.bool_)
    for lane in range(lanes):
        for p in range(count):
            i = order[p]
            on[p] = counted_on_lane(s[i], r[lane, i], length[lane], half_width[lane], vehicle_length, margin)
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


@Kernel
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
