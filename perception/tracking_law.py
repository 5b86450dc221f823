"""The tracker's per-frame law, written once: `track_frame`, one world's multi-object tracker over
fixed-size arrays (at most `TRACKS` tracks a world), a plain function numba compiles. The per-world
`perception.tracking.Tracker` calls it compiled on its world (`perception.tracking_kernels`);
`track_worlds` there loops over the worlds of a batch around the same function
(`perception.tracking.TrackerBatch`).

Each track is two constant-velocity Kalman filters in the reference lane's frame, along the lane
(s [m], ds/dt [m/s]) and across it (d [m], dd/dt [m/s]), each measured by a detection's position
and its reported velocity in that direction (a radar's range rate, a camera's heading), the
velocity's noise `speed_variance`. A frame: every live track is predicted `dt` ahead; each
(track, detection) pair (the detections sorted along the road and bucketed, so each track finds
those within its gate's reach in a step or two and checks only them) whose Mahalanobis distance
(4 degrees of freedom) is within the gate is a candidate, and so is a confirmed track's pair with
a detection outside it but inside its footprint, its vehicle changing lane faster than the
lateral noise allows (within the gate along the lane) or braking as hard as a crash brakes
(`is_manoeuvre`): the track's lateral or longitudinal covariance is then scaled until the
detection is on the gate's edge before the update (`manoeuvre_scales`); candidates are assigned
greedily, nearest first, confirmed tracks before tentative ones (`perception.tracking_search`,
`TENTATIVE_RANK`); assigned tracks are updated, the others coast; a track is confirmed once
`confirm_hits` of its last `confirm_frames` frames had a detection, a tentative one is dropped
once it can no longer reach that, a confirmed one after `coast_frames` frames running without
one; a track confirmed over another confirmed track's vehicle settles which of the two goes, if
either (`settle_twin`); detections left over start tentative tracks in the lowest free slots. The
frame allocates nothing: its working arrays are slices of two flat buffers the
caller keeps (`work_size`), so a world costs the same every frame."""

from __future__ import annotations

import math

import numpy as np
from numba.extending import register_jitable

from perception.track_records import CONFIRMED, FREE, TENTATIVE, Measured, TrackerLaw, Tracks
from perception.tracking_pairs import (
    MANOEUVRE_RANK,
    block_distance,
    is_manoeuvre,
    manoeuvre_scales,
    settle_twin,
)
from perception.tracking_search import assign_greedy_into, fill_buckets, first_at_least, stable_order

GATE_WINDOW_MARGIN_M = 1e-6
"""How far past a track's gate along the road detections are still checked [m] (rounding)."""
TENTATIVE_RANK = 1.0
"""Added, with the gate, to the cost of a tentative track's candidate pairs, so assignment serves
every confirmed track before any tentative one (a cascade): a tentative track started beside a
vehicle (by a phantom, or by a detection noisier than the gate) never takes the detections of
that vehicle's confirmed track and dies, rather than sharing them and living as a second track."""


@register_jitable
def predict_block(
    position: float, velocity: float, pxx: float, pxv: float, pvv: float, acceleration: float, dt: float
) -> tuple[float, float, float, float]:
    """One direction of a track `dt` [s] ahead under constant velocity, with white-noise
    `acceleration` [m/s^2] (std; the discrete Wiener model): its position [m] and its covariance
    block [[pxx, pxv], [pxv, pvv]] (the velocity is unchanged). The laws take and return numbers,
    not a track's rows: a row is an array view whose references numba counts, a cost per call."""
    q = acceleration * acceleration
    return (
        position + dt * velocity,
        pxx + 2 * dt * pxv + dt * dt * pvv + q * dt * dt * dt * dt / 4,
        pxv + dt * pvv + q * dt * dt * dt / 2,
        pvv + q * dt * dt,
    )


@register_jitable
def block_update(
    position: float,
    velocity: float,
    pxx: float,
    pxv: float,
    pvv: float,
    measured_position: float,
    measured_velocity: float,
    r: float,
    rv: float,
) -> tuple[float, float, float, float, float]:
    """One direction's Kalman update of a track's `position` [m], `velocity` [m/s] and covariance
    block [[pxx, pxv], [pxv, pvv]] by a measured position and velocity, variances `r` [m^2] and
    `rv` [m^2/s^2]: the updated position, velocity, pxx, pxv and pvv."""
    a, b, c = pxx + r, pxv, pvv + rv
    det = a * c - b * b
    ia, ib, ic = c / det, -b / det, a / det
    k00, k01 = pxx * ia + pxv * ib, pxx * ib + pxv * ic
    k10, k11 = pxv * ia + pvv * ib, pxv * ib + pvv * ic
    yx, yv = measured_position - position, measured_velocity - velocity
    return (
        position + (k00 * yx + k01 * yv),
        velocity + (k10 * yx + k11 * yv),
        (1 - k00) * pxx - k01 * pxv,
        (1 - k00) * pxv - k01 * pvv,
        -k10 * pxv + (1 - k11) * pvv,
    )


@register_jitable
def _popcount(bits: int) -> int:
    count = 0
    while bits:
        count += bits & 1
        bits >>= 1
    return count


@register_jitable
def work_size(slots: int, detections: int) -> tuple[int, int]:
    """Elements of the integer and the float work buffer `track_frame` takes for `slots` track
    slots and `detections` detections (rows past the ego)."""
    pairs = slots * detections
    return 4 * detections + 1 + 3 * slots + 4 * pairs, detections + 3 * pairs


@register_jitable
def _take(buffer: np.ndarray, at: int, size: int) -> tuple[np.ndarray, int]:
    """`size` elements of `buffer` from `at`, and where the next part starts."""
    return buffer[at : at + size], at + size


@register_jitable
def track_frame(
    law: TrackerLaw,
    tracks: Tracks,
    found: Measured,
    position_variance: float,
    dt: float,
    work_integers: np.ndarray,
    work_floats: np.ndarray,
) -> None:
    """One frame of one world's tracker (see the module): predict every live track `dt` [s] ahead,
    gate, assign, update or coast, confirm or delete, and start tracks for the detections left,
    the detections' positions `position_variance` [m^2] noisy. The work buffers hold at least
    `work_size` elements (fresh ones are taken if not)."""
    slots = len(tracks.status)
    r, rv = position_variance, law.speed_variance
    detections = max(found.rows - 1, 0)
    integers, floats = work_size(slots, detections)
    if len(work_integers) < integers or len(work_floats) < floats:
        work_integers, work_floats = np.empty(integers, dtype=np.int64), np.empty(floats)
    room = slots * detections
    order, at = _take(work_integers, 0, detections)
    starts, at = _take(work_integers, at, detections + 1)
    track_pairs, at = _take(work_integers, at, slots)
    hit, at = _take(work_integers, at, slots)
    live_slots, at = _take(work_integers, at, slots)
    found_pairs, at = _take(work_integers, at, detections)
    assigned, at = _take(work_integers, at, detections)
    pair_track, at = _take(work_integers, at, room)
    pair_found, at = _take(work_integers, at, room)
    contested, at = _take(work_integers, at, room)
    contested_order, at = _take(work_integers, at, room)
    ordered, at = _take(work_floats, 0, detections)
    pair_cost, at = _take(work_floats, at, room)
    contested_cost, at = _take(work_floats, at, room)
    contested_sorted, at = _take(work_floats, at, room)
    state, covariance, status, box = tracks.state, tracks.covariance, tracks.status, tracks.box
    s, d, speed, lateral_speed = found.s, found.d, found.speed, found.lateral_speed
    length, width, heading = found.length, found.width, found.heading
    live = 0
    for t in range(slots):
        if status[t] != FREE:
            state[t, 0], covariance[t, 0], covariance[t, 1], covariance[t, 2] = predict_block(
                state[t, 0], state[t, 1], covariance[t, 0], covariance[t, 1], covariance[t, 2],
                law.longitudinal_acceleration, dt,
            )  # fmt: skip
            state[t, 2], covariance[t, 3], covariance[t, 4], covariance[t, 5] = predict_block(
                state[t, 2], state[t, 3], covariance[t, 3], covariance[t, 4], covariance[t, 5],
                law.lateral_acceleration, dt,
            )  # fmt: skip
            live_slots[live] = t
            live += 1
    pairs = 0
    order = stable_order(s[1 : detections + 1], ordered, order)
    finite = detections
    while finite > 0 and ordered[finite - 1] != ordered[finite - 1]:
        finite -= 1
    low, high, scale = fill_buckets(ordered, finite, starts)
    for i in range(live):
        t = live_slots[i]
        a_s, b_s, c_s = covariance[t, 0] + r, covariance[t, 1], covariance[t, 2] + rv
        a_d, b_d, c_d = covariance[t, 3] + r, covariance[t, 4], covariance[t, 5] + rv
        det_s, det_d = a_s * c_s - b_s * b_s, a_d * c_d - b_d * b_d
        reach_s, reach_d = law.gate * a_s, law.gate * a_d
        confirmed = status[t] == CONFIRMED
        half = np.sqrt(reach_s) + GATE_WINDOW_MARGIN_M
        k = first_at_least(ordered, finite, starts, low, high, scale, state[t, 0] - half)
        end = state[t, 0] + half
        while k < finite and ordered[k] <= end:
            j = order[k] + 1
            k += 1
            ds, dd = s[j] - state[t, 0], d[j] - state[t, 2]
            if ds * ds > reach_s:
                continue
            cost = math.inf
            if dd * dd <= reach_d:
                cost = block_distance(a_s, b_s, c_s, det_s, ds, speed[j] - state[t, 1])
                cost += block_distance(a_d, b_d, c_d, det_d, dd, lateral_speed[j] - state[t, 3])
            gated = cost <= law.gate
            if not gated and confirmed and is_manoeuvre(law, tracks, t, found, j, r, rv, dt):
                gated = True
                cost = law.gate + MANOEUVRE_RANK * (abs(dd) / box[t, 1] + 0.5)
            if gated:
                if status[t] == TENTATIVE:
                    cost += law.gate + TENTATIVE_RANK
                pair_track[pairs], pair_found[pairs], pair_cost[pairs] = t, j - 1, cost
                pairs += 1
    assign_greedy_into(
        pair_track, pair_found, pair_cost, pairs, track_pairs, found_pairs, assigned, contested,
        contested_cost, contested_sorted, contested_order,
    )  # fmt: skip
    hit[:] = 0
    for j in range(detections):
        t = assigned[j]
        if t < 0:
            continue
        hit[t] = 1
        if status[t] == CONFIRMED:
            along_scale, across_scale = manoeuvre_scales(law, tracks, t, found, j + 1, r, rv)
            for c in range(3):
                covariance[t, c] *= along_scale
                covariance[t, 3 + c] *= across_scale
        state[t, 0], state[t, 1], covariance[t, 0], covariance[t, 1], covariance[t, 2] = block_update(
            state[t, 0], state[t, 1], covariance[t, 0], covariance[t, 1], covariance[t, 2],
            s[j + 1], speed[j + 1], r, rv,
        )  # fmt: skip
        state[t, 2], state[t, 3], covariance[t, 3], covariance[t, 4], covariance[t, 5] = block_update(
            state[t, 2], state[t, 3], covariance[t, 3], covariance[t, 4], covariance[t, 5],
            d[j + 1], lateral_speed[j + 1], r, rv,
        )  # fmt: skip
        box[t, 0], box[t, 1], box[t, 2] = length[j + 1], width[j + 1], heading[j + 1]
    window = (1 << law.confirm_frames) - 1
    track_hits, age, misses = tracks.hits, tracks.age, tracks.misses
    for i in range(live):
        t = live_slots[i]
        if status[t] == FREE:
            continue
        track_hits[t] = ((track_hits[t] << 1) | hit[t]) & window
        misses[t] = 0 if hit[t] else misses[t] + 1
        age[t] = min(age[t] + 1, law.confirm_frames)
        hits = _popcount(track_hits[t])
        if status[t] == TENTATIVE:
            if hits >= law.confirm_hits:
                status[t] = CONFIRMED
                settle_twin(tracks, t, hit)
            elif hits + law.confirm_frames - age[t] < law.confirm_hits:
                status[t] = FREE
        elif misses[t] >= law.coast_frames:
            status[t] = FREE
    slot = 0
    for j in range(1, detections + 1):
        if assigned[j - 1] >= 0:
            continue
        while slot < slots and status[slot] != FREE:
            slot += 1
        if slot == slots:
            break
        state[slot, 0], state[slot, 1], state[slot, 2], state[slot, 3] = (
            s[j],
            speed[j],
            d[j],
            lateral_speed[j],
        )
        covariance[slot, 0], covariance[slot, 1], covariance[slot, 2] = r, 0.0, rv
        covariance[slot, 3], covariance[slot, 4], covariance[slot, 5] = r, 0.0, rv
        box[slot, 0], box[slot, 1], box[slot, 2] = length[j], width[j], heading[j]
        track_hits[slot], age[slot], misses[slot] = 1, 1, 0
        status[slot] = CONFIRMED if law.confirm_hits <= 1 else TENTATIVE
        tracks.ident[slot] = tracks.next_ident[0]
        tracks.next_ident[0] += 1


@register_jitable
def confirmed_tracks(
    tracks: Tracks, lane_offsets: np.ndarray, lanes_count: int, slots_out: np.ndarray, lane_out: np.ndarray
) -> int:
    """How many tracks are confirmed; their slots, in slot order, into `slots_out` and the lane
    whose centre (`lane_offsets` of `lanes_count` lanes [m]) is nearest each one's d into
    `lane_out` (the lower lane on a tie)."""
    count = 0
    status, state = tracks.status, tracks.state
    for t in range(len(status)):
        if status[t] != CONFIRMED:
            continue
        nearest, lane = np.inf, 0
        for k in range(lanes_count):
            off = abs(state[t, 2] - lane_offsets[k])
            if off < nearest:
                nearest, lane = off, k
        slots_out[count], lane_out[count] = t, lane
        count += 1
    return count


@register_jitable
def tracked_rows(
    tracks: Tracks, slots: np.ndarray, count: int, lane_heading: float, rows_out: np.ndarray
) -> None:
    """The rows (`ROW_FIELDS`) of the `count` tracks in `slots` into `rows_out`: filtered position;
    the heading of the last detection's box (the lane's heading at the ego `lane_heading` [rad]
    plus the box's angle to it) and the speed along it, the filtered velocity's component in that
    direction (at least 0 [m/s]: a car moves where it points), so the velocity is that speed along
    the box; size of the last detection. The box, not the filtered velocity, gives the direction:
    a stopped car's filtered velocity is the noise of its positions, pointing anywhere."""
    state, box = tracks.state, tracks.box
    for k in range(count):
        t = slots[k]
        cosine, sine = math.cos(box[t, 2]), math.sin(box[t, 2])
        speed = max(state[t, 1] * cosine + state[t, 3] * sine, 0.0)
        rows_out[k, 0], rows_out[k, 1] = state[t, 0], state[t, 2]
        rows_out[k, 2], rows_out[k, 3] = speed * cosine, speed * sine
        rows_out[k, 4] = speed
        rows_out[k, 5] = lane_heading + box[t, 2]
        rows_out[k, 6], rows_out[k, 7] = box[t, 0], box[t, 1]
