"""Which track a detection, or another track, belongs to beyond the plain gate: part of the
tracker's per-frame law (`perception.tracking_law.track_frame`). A pair's Mahalanobis distance in
each direction (`block_distance`, `pair_distances`); a detection a lane change or a crash's
braking took out of its track's gate, still inside its footprint (`is_manoeuvre`), taken after
the track's lateral or longitudinal covariance is scaled to put it on the gate's edge
(`manoeuvre_scales`); and whether two confirmed tracks are one vehicle's (`overlap`,
`centre_inside`), and which of two such goes, if either (`settle_twin`). Plain functions numba
compiles into the law."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from numba.extending import register_jitable

from perception.track_records import CONFIRMED, FREE, Measured, TrackerLaw, Tracks

if TYPE_CHECKING:
    import numpy as np

MANOEUVRE_RANK = 0.5
"""A confirmed track's pair with a detection outside its gate but its vehicle changing lane or
braking hard (`is_manoeuvre`) costs the gate plus this times 0.5-1 (nearer
its centre across the lane, less): after every gated pair of confirmed tracks, before any
tentative track's (`TENTATIVE_RANK`)."""


@register_jitable
def block_distance(a: float, b: float, c: float, det: float, yx: float, yv: float) -> float:
    """Squared Mahalanobis distance in one direction of the position and velocity residuals `yx`
    [m], `yv` [m/s] under the innovation covariance [[a, b], [b, c]], determinant `det` (a c - b^2,
    the same for every detection a track is gated against)."""
    return (c * yx * yx - 2 * b * yx * yv + a * yv * yv) / det


@register_jitable
def overlap(tracks: Tracks, t: int, u: int) -> bool:
    """Whether tracks `t` and `u` overlap: their footprints (each one's last detected length and
    width about its filtered s and d) intersect, which two vehicles cannot."""
    reach_s = (tracks.box[t, 0] + tracks.box[u, 0]) / 2
    reach_d = (tracks.box[t, 1] + tracks.box[u, 1]) / 2
    ds, dd = tracks.state[t, 0] - tracks.state[u, 0], tracks.state[t, 2] - tracks.state[u, 2]
    return abs(ds) < reach_s and abs(dd) < reach_d


@register_jitable
def centre_inside(tracks: Tracks, t: int, u: int) -> bool:
    """Whether one of tracks `t` and `u` has its centre (filtered s and d) inside the other's
    footprint (its last detected length and width): detections scattered over one vehicle, not
    two vehicles touching end to end (wrecks locked together overlap by a crumple's depth)."""
    ds = abs(tracks.state[t, 0] - tracks.state[u, 0])
    dd = abs(tracks.state[t, 2] - tracks.state[u, 2])
    box = tracks.box
    return (ds < box[u, 0] / 2 and dd < box[u, 1] / 2) or (ds < box[t, 0] / 2 and dd < box[t, 1] / 2)


@register_jitable
def inside_footprint(tracks: Tracks, t: int, ds: float, dd: float) -> bool:
    """Whether a detection `ds`, `dd` [m] from track `t`'s predicted centre lies inside its
    footprint (its last detected length and width about that centre): it is that vehicle's (no
    other vehicle's centre fits inside it), however far outside the gate a manoeuvre the motion
    model did not allow took it. False for a NaN offset."""
    return abs(ds) < tracks.box[t, 0] / 2 and abs(dd) < tracks.box[t, 1] / 2


@register_jitable
def pair_distances(
    tracks: Tracks,
    t: int,
    found: Measured,
    j: int,
    r: float,
    rv: float,
    lateral_scale: float,
    longitudinal_scale: float = 1.0,
) -> tuple[float, float]:
    """Squared Mahalanobis distances, along the lane and across it, of detection row `j` of `found`
    from track `t` (predicted, not yet updated), the track's covariance blocks taken
    `longitudinal_scale` and `lateral_scale` times."""
    state, covariance = tracks.state, tracks.covariance
    h = longitudinal_scale
    a_s, b_s, c_s = h * covariance[t, 0] + r, h * covariance[t, 1], h * covariance[t, 2] + rv
    k = lateral_scale
    a_d, b_d, c_d = k * covariance[t, 3] + r, k * covariance[t, 4], k * covariance[t, 5] + rv
    ds, dd = found.s[j] - state[t, 0], found.d[j] - state[t, 2]
    along = block_distance(a_s, b_s, c_s, a_s * c_s - b_s * b_s, ds, found.speed[j] - state[t, 1])
    across = block_distance(a_d, b_d, c_d, a_d * c_d - b_d * b_d, dd, found.lateral_speed[j] - state[t, 3])
    return along, across


MANOEUVRE_SCALE_STEPS = 12
"""Bisection steps of `manoeuvre_scales` (on the logarithm, from 1 to 1e12: the scale within 1 %)."""


@register_jitable
def manoeuvre_scales(
    law: TrackerLaw, tracks: Tracks, t: int, found: Measured, j: int, r: float, rv: float
) -> tuple[float, float]:
    """How many times its longitudinal and its lateral covariance block track `t` takes before its
    update by a detection (row `j` of `found`): 1 and 1 within the gate; for a confirmed track's
    detection outside it and inside its footprint, the least scale of the one block the manoeuvre
    took it out by that puts it on the gate's edge (`is_manoeuvre`): the lateral block for a lane
    change (within the gate along the lane), the longitudinal one for a braking harder than the
    motion model allows. The update then follows the manoeuvre as far as it
    went, no further: a detection just outside the gate by noise moves the track as an ordinary
    one, one a sharp lane change took a metre across moves it almost to the detection, one a crash
    took 1.5 m/s slower in a frame moves its speed almost to the detection's (a fading-memory
    filter's scaling, in one direction)."""
    along, across = pair_distances(tracks, t, found, j, r, rv, 1.0)
    if along + across <= law.gate:
        return 1.0, 1.0
    longitudinal = along > law.gate
    low, high = 0.0, 12.0 * math.log(10.0)
    for _ in range(MANOEUVRE_SCALE_STEPS):
        middle = (low + high) / 2
        scale = math.exp(middle)
        if longitudinal:
            scaled_along, scaled_across = pair_distances(tracks, t, found, j, r, rv, 1.0, scale)
        else:
            scaled_along, scaled_across = along, pair_distances(tracks, t, found, j, r, rv, scale)[1]
        if scaled_along + scaled_across > law.gate:
            low = middle
        else:
            high = middle
    scale = math.exp(high)
    return (scale, 1.0) if longitudinal else (1.0, scale)


CRASH_DECELERATION_PER_S = 1.0
"""The hardest braking a tracked vehicle is taken to do, as a share of its speed a second [1/s]:
a crashed car stops within about a second (highway-env brakes a wreck at its speed per second,
22 m/s^2 at 22 m/s, seven times the filter's white noise)."""


@register_jitable
def is_manoeuvre(
    law: TrackerLaw, tracks: Tracks, t: int, found: Measured, j: int, r: float, rv: float, dt: float
) -> bool:
    """Whether detection row `j` of `found`, outside confirmed track `t`'s gate but inside its
    footprint (`inside_footprint`), is its vehicle manoeuvring beyond the motion model:
    - changing lane: within the gate along the lane, its lateral speed a number (highway vehicles
      swerve across the road far beyond the model's lateral noise; a phantom, which moves at the
      ego's speed, on a car more than about 2 m/s slower or faster is none);
    - or braking as a crash brakes: within the gate across the lane, and slower than the track's
      predicted speed by at most a crash's braking over `dt` [s] (`CRASH_DECELERATION_PER_S`) plus
      three standard deviations of the speed's innovation (a track that coasts while its wreck
      stops is seen braking only through new tracks, each confirmed a few frames late and each
      lagging again: traced, 0.6 s of braking lost, an at-fault collision with a pile-up).
    `manoeuvre_scales` tells the two apart the same way (within the gate along the lane or not)."""
    ds, dd = found.s[j] - tracks.state[t, 0], found.d[j] - tracks.state[t, 2]
    if not inside_footprint(tracks, t, ds, dd):
        return False
    along, across = pair_distances(tracks, t, found, j, r, rv, 1.0)
    if along <= law.gate:
        return found.lateral_speed[j] == found.lateral_speed[j]
    predicted = tracks.state[t, 1]
    drop = predicted - found.speed[j]
    bound = CRASH_DECELERATION_PER_S * abs(predicted) * dt + 3 * math.sqrt(tracks.covariance[t, 2] + rv)
    return 0 < drop <= bound and across <= law.gate


@register_jitable
def settle_twin(tracks: Tracks, t: int, hit: np.ndarray) -> None:
    """Track `t`, confirmed this frame, against the confirmed tracks it overlaps (one vehicle's two
    tracks): one that had no detection this frame has lost its vehicle to `t` (a manoeuvre took
    the detections out of its gate) and is deleted; one that had is the vehicle's own, and `t`
    (fed by phantoms or noise beside it) is deleted instead, when one's centre lies inside the
    other's footprint (`centre_inside`); two detected vehicles that only overlap at their ends
    both stay."""
    for u in range(len(tracks.status)):
        if u == t or tracks.status[u] != CONFIRMED or not overlap(tracks, t, u):
            continue
        if hit[u]:
            if centre_inside(tracks, t, u):
                tracks.status[t] = FREE
                return
            continue
        tracks.status[u] = FREE
