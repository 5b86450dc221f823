"""The tracker's per-frame law, written once: `track_frame`, one world's multi-object tracker over
fixed-size arrays (at most `TRACKS` tracks a world), a plain function numba compiles. The per-world
`perception.tracking.Tracker` calls it compiled on its world (`perception.tracking_kernels`);
`track_worlds` there loops over the worlds of a batch around the same function
(`perception.tracking.TrackerBatch`).

Each track is two constant-velocity Kalman filters in the reference lane's frame, along the lane
(s [m], ds/dt [m/s]) and across it (d [m], dd/dt [m/s]), each measured by a detection's position
and its reported velocity in that direction (a radar's range rate, a camera's heading), the
velocity's noise `speed_variance`. A frame: every live track is predicted `dt` ahead; each
(track, detection) pair (the detections sorted along the road, so each track checks only those
within its gate's reach) whose Mahalanobis distance (4 degrees of freedom) is within the gate is a
candidate; candidates are assigned greedily, nearest first, confirmed tracks before tentative
ones (`assign_greedy`, `TENTATIVE_RANK`); assigned tracks are updated, the others coast; a track
is confirmed once `confirm_hits` of its last `confirm_frames` frames had a detection, a
tentative one is dropped once it can no longer reach that, a confirmed one after `coast_frames`
frames running without one; a track confirmed over another confirmed track's vehicle settles
which of the two goes (`settle_twin`); detections left over start tentative tracks in the lowest
free slots."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable

FREE, TENTATIVE, CONFIRMED = 0, 1, 2
"""A track slot's status."""
GATE_WINDOW_MARGIN_M = 1e-6
"""How far past a track's gate along the road detections are still checked [m] (rounding)."""
TENTATIVE_RANK = 1.0
"""Added, with the gate, to the cost of a tentative track's candidate pairs, so assignment serves
every confirmed track before any tentative one (a cascade): a tentative track started beside a
vehicle (by a phantom, or by a detection noisier than the gate) never takes the detections of
that vehicle's confirmed track and dies, rather than sharing them and living as a second track."""
STATE_SIZE = 4
"""A track's state: s [m], ds/dt [m/s], d [m], dd/dt [m/s]."""
ROW_FIELDS = 8
"""A reported track's row (`tracked_rows`): s, d [m], velocity along and across the lane, speed
[m/s], heading [rad], length, width [m]."""
COVARIANCE_SIZE = 6
"""A track's covariance, two symmetric 2 x 2 blocks: [P_ss, P_sv, P_vv, P_dd, P_dw, P_ww]."""


class TrackerLaw(NamedTuple):
    """The tracker's settings as `track_frame` reads them: confirmation `confirm_hits` of the last
    `confirm_frames` frames (at most 62), deletion after `coast_frames` missed frames running,
    the gate (squared Mahalanobis distance, 4 degrees of freedom), the white-noise accelerations
    [m/s^2] of the longitudinal and lateral filters, and the variance of a reported velocity
    component [m^2/s^2]."""

    confirm_hits: int
    confirm_frames: int
    coast_frames: int
    gate: float
    longitudinal_acceleration: float
    lateral_acceleration: float
    speed_variance: float


class Tracks(NamedTuple):
    """One world's tracks, a slot each: `state` (slots, 4) [s, ds/dt, d, dd/dt], `covariance`
    (slots, 6), `hits` the last frames' detections as bits (newest lowest), `age` frames since
    birth, `misses` frames running without a detection, `status` (`FREE`, `TENTATIVE`,
    `CONFIRMED`), `ident` each track's id, `size` (slots, 2) length and width [m] of its last
    detection, and `next_ident` (1,) the id the next track gets."""

    state: np.ndarray
    covariance: np.ndarray
    hits: np.ndarray
    age: np.ndarray
    misses: np.ndarray
    status: np.ndarray
    ident: np.ndarray
    size: np.ndarray
    next_ident: np.ndarray


class MeasuredWorlds(NamedTuple):
    """Many worlds' detections: `Measured`'s fields with a first axis of worlds."""

    rows: np.ndarray
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    lateral_speed: np.ndarray
    length: np.ndarray
    width: np.ndarray


class Measured(NamedTuple):
    """One frame's detections, rows 1 to `rows` - 1 (row 0 is the ego, never tracked): `s`, `d`
    [m] in the reference lane's frame, `speed` along the lane and `lateral_speed` across it [m/s],
    `length`, `width` [m]."""

    rows: int
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    lateral_speed: np.ndarray
    length: np.ndarray
    width: np.ndarray


@register_jitable
def predict(state: np.ndarray, covariance: np.ndarray, law: TrackerLaw, dt: float) -> None:
    """One track's state and covariance `dt` [s] ahead under constant velocity, with white-noise
    acceleration (the discrete Wiener model) in each direction."""
    state[0] += dt * state[1]
    state[2] += dt * state[3]
    _predict_block(covariance, 0, law.longitudinal_acceleration, dt)
    _predict_block(covariance, 3, law.lateral_acceleration, dt)


@register_jitable
def _predict_block(covariance: np.ndarray, at: int, acceleration: float, dt: float) -> None:
    """The 2 x 2 block of `covariance` from `at` [position, velocity] `dt` [s] ahead, with white
    noise `acceleration` [m/s^2] (std)."""
    q = acceleration * acceleration
    pxx, pxv, pvv = covariance[at], covariance[at + 1], covariance[at + 2]
    covariance[at] = pxx + 2 * dt * pxv + dt * dt * pvv + q * dt * dt * dt * dt / 4
    covariance[at + 1] = pxv + dt * pvv + q * dt * dt * dt / 2
    covariance[at + 2] = pvv + q * dt * dt


@register_jitable
def block_distance(
    state: np.ndarray, covariance: np.ndarray, at: int, position: float, velocity: float, r: float, rv: float
) -> float:
    """Squared Mahalanobis distance in one direction (the state's and covariance's block from
    `at`) of a measured `position` [m] and `velocity` [m/s], variances `r` [m^2] and `rv` [m^2/s^2]."""
    a, b, c = covariance[at] + r, covariance[at + 1], covariance[at + 2] + rv
    yx, yv = position - state[at // 3 * 2], velocity - state[at // 3 * 2 + 1]
    return (c * yx * yx - 2 * b * yx * yv + a * yv * yv) / (a * c - b * b)


@register_jitable
def block_update(
    state: np.ndarray, covariance: np.ndarray, at: int, position: float, velocity: float, r: float, rv: float
) -> None:
    """One direction's Kalman update (the covariance block from `at`) by a measured `position` [m]
    and `velocity` [m/s]."""
    x = at // 3 * 2
    pxx, pxv, pvv = covariance[at], covariance[at + 1], covariance[at + 2]
    a, b, c = pxx + r, pxv, pvv + rv
    det = a * c - b * b
    ia, ib, ic = c / det, -b / det, a / det
    k00, k01 = pxx * ia + pxv * ib, pxx * ib + pxv * ic
    k10, k11 = pxv * ia + pvv * ib, pxv * ib + pvv * ic
    yx, yv = position - state[x], velocity - state[x + 1]
    state[x] += k00 * yx + k01 * yv
    state[x + 1] += k10 * yx + k11 * yv
    covariance[at] = (1 - k00) * pxx - k01 * pxv
    covariance[at + 1] = (1 - k00) * pxv - k01 * pvv
    covariance[at + 2] = -k10 * pxv + (1 - k11) * pvv


@register_jitable
def distance(
    state: np.ndarray, covariance: np.ndarray, found: Measured, j: int, r: float, rv: float
) -> float:
    """Squared Mahalanobis distance of detection `j` of `found` from a track, its positions' variance
    `r` [m^2], its velocities' `rv` [m^2/s^2]."""
    along = block_distance(state, covariance, 0, found.s[j], found.speed[j], r, rv)
    return along + block_distance(state, covariance, 3, found.d[j], found.lateral_speed[j], r, rv)


@register_jitable
def update(state: np.ndarray, covariance: np.ndarray, found: Measured, j: int, r: float, rv: float) -> None:
    """One track's Kalman update by detection `j` of `found`."""
    block_update(state, covariance, 0, found.s[j], found.speed[j], r, rv)
    block_update(state, covariance, 3, found.d[j], found.lateral_speed[j], r, rv)


@register_jitable
def assign_greedy(
    pair_track: np.ndarray,
    pair_found: np.ndarray,
    pair_cost: np.ndarray,
    pairs: int,
    tracks: int,
    found: int,
) -> np.ndarray:
    """(found,) the track each detection is assigned (-1: none), from the `pairs` gated candidates
    (track, detection, cost): the cheapest pair first, then the cheapest left whose track and
    detection are both free (global nearest neighbour, greedy; ties to the earlier pair). A pair
    whose track and detection are in no other pair is taken whatever the order, so only the
    contested pairs are sorted (most tracks on a highway have one uncontested candidate). Written
    by hand because the batch compiles it: scipy's `linear_sum_assignment` cannot run inside numba.
    Inside the gate vehicles stand a car length apart and detections are metres apart at most, so
    the nearest pair is almost always the optimal assignment's; the tests check it against scipy's
    on such scenes."""
    track_pairs = np.zeros(tracks, dtype=np.int64)
    found_pairs = np.zeros(found, dtype=np.int64)
    for k in range(pairs):
        track_pairs[pair_track[k]] += 1
        found_pairs[pair_found[k]] += 1
    assigned = np.full(found, -1, dtype=np.int64)
    contested = np.empty(pairs, dtype=np.int64)
    contested_cost = np.empty(pairs)
    count = 0
    for k in range(pairs):
        t, j = pair_track[k], pair_found[k]
        if track_pairs[t] == 1 and found_pairs[j] == 1:
            assigned[j] = t
        else:
            contested[count], contested_cost[count] = k, pair_cost[k]
            count += 1
    order = np.argsort(contested_cost[:count], kind="mergesort")
    track_taken = track_pairs == 0
    for i in order:
        k = contested[i]
        t, j = pair_track[k], pair_found[k]
        if track_taken[t] or assigned[j] >= 0:
            continue
        track_taken[t] = True
        assigned[j] = t
    return assigned


@register_jitable
def stable_order(values: np.ndarray, ordered: np.ndarray) -> np.ndarray:
    """The indices that sort `values` ascending, ties in their order (numpy's mergesort), the sorted
    values into `ordered`: an insertion sort, as a sensor reports vehicles nearly in order along the
    road; past `len(values)` moves or on a NaN, numpy's mergesort (the same order)."""
    n = len(values)
    order = np.arange(n)
    moves = 0
    for i in range(n):
        value, k = values[i], i
        while k > 0 and ordered[k - 1] > value:
            ordered[k], order[k] = ordered[k - 1], order[k - 1]
            k -= 1
            moves += 1
        ordered[k], order[k] = value, i
        if moves > n or value != value:
            order = np.argsort(values, kind="mergesort")
            for m in range(n):
                ordered[m] = values[order[m]]
            return order
    return order


@register_jitable
def overlap(tracks: Tracks, t: int, u: int) -> bool:
    """Whether tracks `t` and `u` overlap: their footprints (each one's last detected length and
    width about its filtered s and d) intersect, which two vehicles cannot."""
    reach_s = (tracks.size[t, 0] + tracks.size[u, 0]) / 2
    reach_d = (tracks.size[t, 1] + tracks.size[u, 1]) / 2
    ds, dd = tracks.state[t, 0] - tracks.state[u, 0], tracks.state[t, 2] - tracks.state[u, 2]
    return abs(ds) < reach_s and abs(dd) < reach_d


@register_jitable
def settle_twin(tracks: Tracks, t: int, hit: np.ndarray) -> None:
    """Track `t`, confirmed this frame, against the confirmed tracks it overlaps (one vehicle's two
    tracks): one that had no detection this frame has lost its vehicle to `t` (a manoeuvre took
    the detections out of its gate) and is deleted; one that had is the vehicle's own, and `t`
    (fed by phantoms or noise beside it) is deleted instead."""
    for u in range(len(tracks.status)):
        if u == t or tracks.status[u] != CONFIRMED or not overlap(tracks, t, u):
            continue
        if hit[u]:
            tracks.status[t] = FREE
            return
        tracks.status[u] = FREE


@register_jitable
def _popcount(bits: int) -> int:
    count = 0
    while bits:
        count += bits & 1
        bits >>= 1
    return count


@register_jitable
def track_frame(
    law: TrackerLaw, tracks: Tracks, found: Measured, position_variance: float, dt: float
) -> None:
    """One frame of one world's tracker (see the module): predict every live track `dt` [s] ahead,
    gate, assign, update or coast, confirm or delete, and start tracks for the detections left,
    the detections' positions `position_variance` [m^2] noisy."""
    slots = len(tracks.status)
    r, rv = position_variance, law.speed_variance
    live = 0
    for t in range(slots):
        if tracks.status[t] != FREE:
            predict(tracks.state[t], tracks.covariance[t], law, dt)
            live += 1
    detections = max(found.rows - 1, 0)
    pair_track = np.empty(live * detections, dtype=np.int64)
    pair_found = np.empty(live * detections, dtype=np.int64)
    pair_cost = np.empty(live * detections)
    pairs = 0
    ordered = np.empty(detections)
    order = stable_order(found.s[1 : detections + 1], ordered)
    for t in range(slots):
        if tracks.status[t] == FREE:
            continue
        state, covariance = tracks.state[t], tracks.covariance[t]
        reach_s = law.gate * (covariance[0] + r)
        reach_d = law.gate * (covariance[3] + r)
        half = np.sqrt(reach_s) + GATE_WINDOW_MARGIN_M
        first = np.searchsorted(ordered, state[0] - half, side="left")
        last = np.searchsorted(ordered, state[0] + half, side="right")
        for k in range(first, last):
            j = order[k]
            ds, dd = found.s[j + 1] - state[0], found.d[j + 1] - state[2]
            if ds * ds > reach_s or dd * dd > reach_d:
                continue
            cost = distance(state, covariance, found, j + 1, r, rv)
            if cost <= law.gate:
                if tracks.status[t] == TENTATIVE:
                    cost += law.gate + TENTATIVE_RANK
                pair_track[pairs], pair_found[pairs], pair_cost[pairs] = t, j, cost
                pairs += 1
    assigned = assign_greedy(pair_track, pair_found, pair_cost, pairs, slots, detections)
    hit = np.zeros(slots, dtype=np.bool_)
    for j in range(detections):
        t = assigned[j]
        if t >= 0:
            hit[t] = True
            update(tracks.state[t], tracks.covariance[t], found, j + 1, r, rv)
            tracks.size[t, 0], tracks.size[t, 1] = found.length[j + 1], found.width[j + 1]
    window = (1 << law.confirm_frames) - 1
    for t in range(slots):
        if tracks.status[t] == FREE:
            continue
        tracks.hits[t] = ((tracks.hits[t] << 1) | (1 if hit[t] else 0)) & window
        tracks.misses[t] = 0 if hit[t] else tracks.misses[t] + 1
        tracks.age[t] = min(tracks.age[t] + 1, law.confirm_frames)
        hits = _popcount(tracks.hits[t])
        if tracks.status[t] == TENTATIVE:
            if hits >= law.confirm_hits:
                tracks.status[t] = CONFIRMED
                settle_twin(tracks, t, hit)
            elif hits + law.confirm_frames - tracks.age[t] < law.confirm_hits:
                tracks.status[t] = FREE
        elif tracks.misses[t] >= law.coast_frames:
            tracks.status[t] = FREE
    slot = 0
    for j in range(detections):
        if assigned[j] >= 0:
            continue
        while slot < slots and tracks.status[slot] != FREE:
            slot += 1
        if slot == slots:
            break
        tracks.state[slot, 0], tracks.state[slot, 1] = found.s[j + 1], found.speed[j + 1]
        tracks.state[slot, 2], tracks.state[slot, 3] = found.d[j + 1], found.lateral_speed[j + 1]
        covariance = tracks.covariance[slot]
        covariance[0], covariance[1], covariance[2] = r, 0.0, rv
        covariance[3], covariance[4], covariance[5] = r, 0.0, rv
        tracks.hits[slot], tracks.age[slot], tracks.misses[slot] = 1, 1, 0
        tracks.status[slot] = CONFIRMED if law.confirm_hits <= 1 else TENTATIVE
        tracks.ident[slot] = tracks.next_ident[0]
        tracks.next_ident[0] += 1
        tracks.size[slot, 0], tracks.size[slot, 1] = found.length[j + 1], found.width[j + 1]


@register_jitable
def confirmed_tracks(
    tracks: Tracks, lane_offsets: np.ndarray, lanes_count: int, slots_out: np.ndarray, lane_out: np.ndarray
) -> int:
    """How many tracks are confirmed; their slots, in slot order, into `slots_out` and the lane
    whose centre (`lane_offsets` of `lanes_count` lanes [m]) is nearest each one's d into
    `lane_out` (the lower lane on a tie)."""
    count = 0
    for t in range(len(tracks.status)):
        if tracks.status[t] != CONFIRMED:
            continue
        nearest, lane = np.inf, 0
        for k in range(lanes_count):
            off = abs(tracks.state[t, 2] - lane_offsets[k])
            if off < nearest:
                nearest, lane = off, k
        slots_out[count], lane_out[count] = t, lane
        count += 1
    return count


@register_jitable
def tracked_rows(
    tracks: Tracks, slots: np.ndarray, count: int, lane_heading: float, rows_out: np.ndarray
) -> None:
    """The rows (`ROW_FIELDS`) of the `count` tracks in `slots` into `rows_out`: filtered position
    and velocity, speed and heading from the velocity (the lane's heading at the ego
    `lane_heading` [rad] plus the velocity's angle to it), size of the last detection."""
    for k in range(count):
        t = slots[k]
        along, across = tracks.state[t, 1], tracks.state[t, 3]
        rows_out[k, 0], rows_out[k, 1] = tracks.state[t, 0], tracks.state[t, 2]
        rows_out[k, 2], rows_out[k, 3] = along, across
        rows_out[k, 4] = math.hypot(along, across)
        rows_out[k, 5] = lane_heading + math.atan2(across, along)
        rows_out[k, 6], rows_out[k, 7] = tracks.size[t, 0], tracks.size[t, 1]
