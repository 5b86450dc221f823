"""Compiled (numba) kernels of a batch of traffic worlds over [worlds, vehicles] arrays: each world's
lane coordinates and lane occupancy, highway-env's neighbour search, the MOBIL decisions in road
order, the closest lane and the collision candidates. Vehicle `i` of world `w` is row `w * V + i`
of the flattened arrays (V vehicles a world; a world's vehicles fill its first rows, in road
order). Sums, products, comparisons and the float modulo only, in highway-env's operation order
(numpy's bits, numba contracts no multiply-add); numpy's transcendental calls and dot products run
between the kernels (`stack.sim.batch.traffic`)."""

from __future__ import annotations

import numpy as np
from numba import njit

from common.compiled import Kernel
from stack.sim.batch.segment_kernels import segment_of
from stack.sim.vector.dynamics import desired_gap, mobil_accepts
from stack.sim.vector.geometry_kernels import (
    closest_lanes,
    could_touch,
    counted_on_lane,
    lane_coordinates,
    within_reach,
)

_closest_lanes = closest_lanes.compiled


@Kernel
def lane_frames(
    count: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    lane_count: np.ndarray,
    start: np.ndarray,
    direction: np.ndarray,
    lateral: np.ndarray,
    length: np.ndarray,
    half_width: np.ndarray,
    vehicle_length: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Per world (`count` vehicles at (`x`, `y`) [m], (W, V); `lane_count` lanes with `start`
    (W, L, 2) [m], shared unit `direction` (W, 2), unit `lateral` (W, L, 2), `length` and
    `half_width` (W, L) [m]): s (W, V) [m] along the lanes, r (W, L, V) [m] across each, and per
    lane the vehicles `Road.neighbour_vehicles` counts on it (`on_lane` with a lateral `margin`,
    `vehicle_length` beyond both ends) in road order, (W, L, V), and how many, (W, L)."""
    worlds, width = x.shape
    lanes = start.shape[1]
    s = np.zeros((worlds, width))
    r = np.zeros((worlds, lanes, width))
    on = np.full((worlds, lanes, width), -1, dtype=np.int64)
    on_count = np.zeros((worlds, lanes), dtype=np.int64)
    for w in range(worlds):
        n, used = count[w], lane_count[w]
        s_w, r_w = lane_coordinates(x[w, :n], y[w, :n], start[w, :used], direction[w], lateral[w, :used])
        s[w, :n] = s_w
        r[w, :used, :n] = r_w
        for lane in range(used):
            k = 0
            for i in range(n):
                if counted_on_lane(
                    s_w[i], r_w[lane, i], length[w, lane], half_width[w, lane], vehicle_length, margin
                ):
                    on[w, lane, k] = i
                    k += 1
            on_count[w, lane] = k
    return s, r, on, on_count


@njit(cache=True, nogil=True)
def _neighbours(
    me: int,
    s_me: float,
    on: np.ndarray,
    on_count: int,
    s: np.ndarray,
    start: float,
    length: float,
    vehicle_length: float,
) -> tuple[int, int]:  # pragma: no cover - compiled
    """(front, rear) of vehicle `me` at `s_me` [m] among the `on_count` vehicles `on` a lane (road
    order), as `Road.neighbour_vehicles` picks them: front the nearest at s_v >= s (the last in road
    order on ties), rear the nearest at s_v < s (the first on ties), itself excluded; -1 for none.
    Only vehicles on the lane's segment (from `start`, `length` long [m]) count, as `on_lane` counts
    them, to `vehicle_length` [m] beyond both ends (a world of one segment: start 0, length inf)."""
    front, rear = -1, -1
    s_front, s_rear = 0.0, 0.0
    for k in range(on_count):
        v = on[k]
        if v == me:
            continue
        s_v = s[v]
        if not (-vehicle_length <= s_v - start and s_v - start < length + vehicle_length):
            continue
        if s_me <= s_v and (front < 0 or s_v <= s_front):
            front, s_front = v, s_v
        if s_v < s_me and (rear < 0 or s_v > s_rear):
            rear, s_rear = v, s_v
    return front, rear


@Kernel
def lane_neighbours(
    rows: np.ndarray,
    lane_rows: np.ndarray,
    s: np.ndarray,
    on: np.ndarray,
    on_count: np.ndarray,
    segment_rows: np.ndarray,
    segment_start: np.ndarray,
    segment_length: np.ndarray,
    vehicle_length: float,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Flat rows of the (front, rear) of the vehicles in flat `rows`, each on its lane of
    `lane_rows` in its segment of `segment_rows` (of `segment_start` and `segment_length`, (W, K)
    [m]), from `lane_frames`' s (W, V) and occupancy (-1: none)."""
    width = s.shape[1]
    front = np.empty(rows.shape[0], dtype=np.int64)
    rear = np.empty(rows.shape[0], dtype=np.int64)
    for k in range(rows.shape[0]):
        w, i = rows[k] // width, rows[k] % width
        lane, segment = lane_rows[k], segment_rows[k]
        f, b = _neighbours(
            i, s[w, i], on[w, lane], on_count[w, lane], s[w],
            segment_start[w, segment], segment_length[w, segment], vehicle_length,
        )  # fmt: skip
        front[k] = w * width + f if f >= 0 else -1
        rear[k] = w * width + b if b >= 0 else -1
    return front, rear


@Kernel
def plan_decisions(
    drivers: np.ndarray,
    lane: np.ndarray,
    target: np.ndarray,
    speed: np.ndarray,
    timer: np.ndarray,
    enable_lane_change: np.ndarray,
    controlled: np.ndarray,
    distance_wanted: np.ndarray,
    count: np.ndarray,
    s: np.ndarray,
    r: np.ndarray,
    on: np.ndarray,
    on_count: np.ndarray,
    lane_count: np.ndarray,
    lane_length: np.ndarray,
    half_width: np.ndarray,
    forbidden: np.ndarray,
    lane_change_delay: np.ndarray,
    time_wanted: np.ndarray,
    braking_term: np.ndarray,
    segment_start: np.ndarray,
    segment_length: np.ndarray,
    segment_count: np.ndarray,
    vehicle_length: float,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]:  # pragma: no cover - compiled
    """What the drivers' (flat rows `drivers`, road order) `change_lane_policy` needs, from their
    state at the frame's start (flat arrays, (W, V) for s, (W, L, V) for r):

    - each driver's own-lane (front, rear), on the segment its position is on (`segment_of`; the
      segments of each world (W, K): `segment_start`, `segment_length` [m], `segment_count`);
    - the MOBIL candidates of the drivers due to decide (lane-change timer past their
      `lane_change_delay` [s], on their target lane, lane changes on, |speed| >= 1 m/s): one per
      reachable side lane, in `side_lanes`' order: the driver's position k in `drivers`, the side
      lane's row, its (front, rear) there;
    - the abort candidates of the drivers changing lane: (k, row of a controlled vehicle ahead
      not on k's target lane, closer than its largest possible desired gap), in road order; the
      exact test needs the closing speed's dot product and the others' targets as the act finds
      them (`decide`).
    """
    width = s.shape[1]
    drivers_count = drivers.shape[0]
    own_front = np.empty(drivers_count, dtype=np.int64)
    own_rear = np.empty(drivers_count, dtype=np.int64)
    side_driver = np.empty(2 * drivers_count, dtype=np.int64)
    side_lane = np.empty(2 * drivers_count, dtype=np.int64)
    side_front = np.empty(2 * drivers_count, dtype=np.int64)
    side_rear = np.empty(2 * drivers_count, dtype=np.int64)
    sides = 0
    pair_capacity = max(drivers_count, 16)
    pair_driver = np.empty(pair_capacity, dtype=np.int64)
    pair_other = np.empty(pair_capacity, dtype=np.int64)
    pairs = 0
    for k in range(drivers_count):
        g = drivers[k]
        w, i = g // width, g % width
        s_w, s_me = s[w], s[w, i]
        own = lane[g]
        segment = segment_of(s_me, segment_start[w], segment_length[w], segment_count[w])
        start, length = segment_start[w, segment], segment_length[w, segment]
        f, b = _neighbours(i, s_me, on[w, own], on_count[w, own], s_w, start, length, vehicle_length)
        own_front[k] = w * width + f if f >= 0 else -1
        own_rear[k] = w * width + b if b >= 0 else -1
        if not enable_lane_change[g]:
            continue
        if own != target[g]:
            goal = target[g]
            reach = abs(speed[g])
            for v in range(count[w]):
                other = w * width + v
                if v == i or not controlled[other] or lane[other] == goal:
                    continue
                d = s_w[v] - s_me
                largest = desired_gap(
                    distance_wanted[g], time_wanted[g], braking_term[g], reach, reach + abs(speed[other])
                )
                if 0 < d and d < largest * (1 + 1e-9) + 1e-9:
                    if pairs == pair_capacity:
                        pair_capacity *= 2
                        pair_driver = np.concatenate((pair_driver, np.empty_like(pair_driver)))
                        pair_other = np.concatenate((pair_other, np.empty_like(pair_other)))
                    pair_driver[pairs], pair_other[pairs] = k, other
                    pairs += 1
            continue
        if not lane_change_delay[g] < timer[g] or abs(speed[g]) < 1:
            continue
        for side in (own - 1, own + 1):
            if side < 0 or side >= lane_count[w] or forbidden[w, side]:
                continue
            near = abs(r[w, side, i]) <= 2 * (2 * half_width[w, side])
            if not (near and 0 <= s_me and s_me < lane_length[w, side] + vehicle_length):
                continue
            f, b = _neighbours(i, s_me, on[w, side], on_count[w, side], s_w, start, length, vehicle_length)
            side_driver[sides], side_lane[sides] = k, side
            side_front[sides] = w * width + f if f >= 0 else -1
            side_rear[sides] = w * width + b if b >= 0 else -1
            sides += 1
    return (
        own_front,
        own_rear,
        side_driver[:sides],
        side_lane[:sides],
        side_front[:sides],
        side_rear[:sides],
        pair_driver[:pairs],
        pair_other[:pairs],
    )


@Kernel
def decide(
    drivers: np.ndarray,
    lane: np.ndarray,
    target: np.ndarray,
    timer: np.ndarray,
    enable_lane_change: np.ndarray,
    speed: np.ndarray,
    s: np.ndarray,
    distance_wanted: np.ndarray,
    side_driver: np.ndarray,
    side_lane: np.ndarray,
    side_accelerations: np.ndarray,
    pair_driver: np.ndarray,
    pair_other: np.ndarray,
    pair_closing: np.ndarray,
    lane_change_delay: np.ndarray,
    time_wanted: np.ndarray,
    braking_term: np.ndarray,
    politeness: np.ndarray,
    min_gain: np.ndarray,
    max_braking_imposed: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`IDMVehicle.change_lane_policy` of every driver in road order, on `plan_decisions`'
    candidates: sets `target` (lane rows) and `timer` [s] in place. A driver changing lane aborts
    (targets its own lane again) behind the first controlled vehicle in road order that targets
    the same lane from another one, ahead closer than its desired gap (`pair_closing`: the closing
    speed's dot product per abort candidate [m/s]); a driver due to decide resets its timer and
    takes the last side lane MOBIL accepts (`side_accelerations`: six rows of IDM accelerations
    [m/s^2] per candidate: new rear behind new front, new rear behind the driver, the driver behind
    the new front, the driver behind its own front, its own rear behind it, its own rear behind
    its own front)."""
    sides = side_driver.shape[0]
    side = 0
    pair = 0
    for k in range(drivers.shape[0]):
        g = drivers[k]
        if not enable_lane_change[g]:
            continue
        if lane[g] != target[g]:
            goal = target[g]
            while pair < pair_driver.shape[0] and pair_driver[pair] == k:
                other = pair_other[pair]
                if target[other] == goal:
                    d = s[other] - s[g]
                    desired = desired_gap(
                        distance_wanted[g], time_wanted[g], braking_term[g], speed[g], pair_closing[pair]
                    )
                    if 0 < d and d < desired:
                        target[g] = lane[g]
                        break
                pair += 1
            while pair < pair_driver.shape[0] and pair_driver[pair] == k:
                pair += 1
            continue
        if not lane_change_delay[g] < timer[g]:
            continue
        timer[g] = 0.0
        while side < sides and side_driver[side] == k:
            a = side_accelerations[:, side]
            if mobil_accepts(
                a[0], a[1], a[2], a[3], a[4], a[5], politeness[g], min_gain[g], max_braking_imposed[g]
            ):
                target[g] = side_lane[side]
            side += 1


@Kernel
def closest_lane_rows(
    count: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    lane_count: np.ndarray,
    start: np.ndarray,
    direction: np.ndarray,
    lateral: np.ndarray,
    length: np.ndarray,
    lane_heading: np.ndarray,
) -> np.ndarray:  # pragma: no cover - compiled
    """Each world's vehicles' closest lane rows (W, V) by highway-env's `distance_with_heading`
    (`stack.sim.vector.geometry_kernels.closest_lanes`), -1 in the empty rows."""
    rows = np.full(x.shape, -1, dtype=np.int64)
    for w in range(x.shape[0]):
        n, used = count[w], lane_count[w]
        rows[w, :n] = _closest_lanes(
            x[w, :n],
            y[w, :n],
            heading[w, :n],
            start[w, :used],
            direction[w],
            lateral[w, :used],
            length[w, :used],
            lane_heading[w, :used],
        )
    return rows


@Kernel
def collision_candidates(
    count: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    speed: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    diagonal: np.ndarray,
    direction: np.ndarray,
    dt: float,
    broad_margin: float,
    separation_margin: float,
) -> np.ndarray:  # pragma: no cover - compiled
    """The (world, i, j) triples, i < j, by world then i then j, of the vehicle pairs that
    `stack.sim.vector.geometry_kernels.could_touch` keeps (a superset of the pairs highway-env's collision
    test finds touching or about to over `dt` [s]), from a sweep along each world's lane
    `direction` (an axis): no pair further apart along it than the largest reach is tested."""
    found = np.empty((16, 3), dtype=np.int64)
    total = 0
    pairs = np.empty((16, 2), dtype=np.int64)
    for w in range(x.shape[0]):
        n = count[w]
        if n < 2:
            continue
        x_w, y_w, speed_w = x[w, :n], y[w, :n], speed[w, :n]
        cos, sin = np.cos(heading[w, :n]), np.sin(heading[w, :n])
        along = x_w * direction[w, 0] + y_w * direction[w, 1]
        order = np.argsort(along, kind="mergesort")
        reach = (diagonal[w, :n].max() + max(speed_w.max(), 0.0) * dt + broad_margin) * (1 + 1e-9)
        kept = 0
        for p in range(n):
            for q in range(p + 1, n):
                if along[order[q]] - along[order[p]] > reach:
                    break
                a, b = min(order[p], order[q]), max(order[p], order[q])
                if not within_reach(a, b, x_w, y_w, speed_w, diagonal[w, :n], dt, broad_margin):
                    continue
                close = could_touch(
                    a, b, x_w, y_w, cos, sin, speed_w, length[w, :n], width[w, :n], diagonal[w, :n], dt,
                    broad_margin, separation_margin,
                )  # fmt: skip
                if close:
                    if kept == pairs.shape[0]:
                        pairs = np.concatenate((pairs, np.empty_like(pairs)))
                    pairs[kept, 0], pairs[kept, 1] = a, b
                    kept += 1
        if kept:
            sorted_pairs = pairs[:kept][np.argsort(pairs[:kept, 0] * n + pairs[:kept, 1])]
            while total + kept > found.shape[0]:
                found = np.concatenate((found, np.empty_like(found)))
            found[total : total + kept, 0] = w
            found[total : total + kept, 1:] = sorted_pairs
            total += kept
    return found[:total]
