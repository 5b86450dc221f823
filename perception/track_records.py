"""The tracker's records: a track slot's status, one world's tracks (`Tracks`), a frame's
detections (`Measured`, many worlds' `MeasuredWorlds`) and the law's settings (`TrackerLaw`), as
the per-frame law (`perception.tracking_law`) and its callers share them."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

FREE, TENTATIVE, CONFIRMED = 0, 1, 2
"""A track slot's status."""
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
    `CONFIRMED`), `ident` each track's id, `box` (slots, 3) its last detection's length, width [m]
    and heading to the lane [rad], and `next_ident` (1,) the id the next track gets."""

    state: np.ndarray
    covariance: np.ndarray
    hits: np.ndarray
    age: np.ndarray
    misses: np.ndarray
    status: np.ndarray
    ident: np.ndarray
    box: np.ndarray
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
    heading: np.ndarray


class Measured(NamedTuple):
    """One frame's detections, rows 1 to `rows` - 1 (row 0 is the ego, never tracked): `s`, `d`
    [m] in the reference lane's frame, `speed` along the lane and `lateral_speed` across it [m/s],
    `length`, `width` [m], `heading` to the lane [rad]."""

    rows: int
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    lateral_speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    heading: np.ndarray
