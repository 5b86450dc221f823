"""Compiled (numba) kernels of a through road's segments (`stack.sim.batch.through_road`): which
segment a vehicle is on, as highway-env's closest-lane search picks it, and which drivers already
follow the next segment's lane. Rows as `stack.sim.batch.traffic_kernels` takes them."""

from __future__ import annotations

import numpy as np
from numba import njit

from common.compiled import Kernel


@njit(cache=True, nogil=True)
def segment_of(
    s: float, start: np.ndarray, length: np.ndarray, count: int
) -> int:  # pragma: no cover - compiled
    """The segment (of `count`, starting at `start` along the road and `length` long [m]) whose
    lane highway-env's closest-lane search picks for an object at `s` [m] on a through road: the
    first whose end is not behind it (a tie at a boundary goes to the earlier segment)."""
    for k in range(count - 1):
        if s - start[k] <= length[k]:
            return k
    return count - 1


@Kernel
def segments_of(
    rows: np.ndarray,
    s: np.ndarray,
    segment_start: np.ndarray,
    segment_length: np.ndarray,
    segment_count: np.ndarray,
) -> np.ndarray:  # pragma: no cover - compiled
    """The segment (`segment_of`) of each vehicle of flat `rows`, from `lane_frames`' s (W, V)."""
    width = s.shape[1]
    segments = np.empty(rows.shape[0], dtype=np.int64)
    for k in range(rows.shape[0]):
        w, i = rows[k] // width, rows[k] % width
        segments[k] = segment_of(s[w, i], segment_start[w], segment_length[w], segment_count[w])
    return segments


@Kernel
def crossing_drivers(
    drivers: np.ndarray,
    s: np.ndarray,
    segment_start: np.ndarray,
    segment_length: np.ndarray,
    segment_count: np.ndarray,
    vehicle_length: float,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """The drivers (positions in `drivers`, flat rows) whose route has switched their target lane to
    the next segment's while they are still on their own (`follow_road`: past `vehicle_length` / 2
    [m] before their segment's end), and that next segment: highway-env's IDM then takes the lower
    of its accelerations behind the leaders on both (`IDMVehicle.act`)."""
    width = s.shape[1]
    found = np.empty(drivers.shape[0], dtype=np.int64)
    following = np.empty(drivers.shape[0], dtype=np.int64)
    total = 0
    for k in range(drivers.shape[0]):
        w, i = drivers[k] // width, drivers[k] % width
        count = segment_count[w]
        if count < 2:
            continue
        segment = segment_of(s[w, i], segment_start[w], segment_length[w], count)
        if (
            segment + 1 < count
            and s[w, i] - segment_start[w, segment] > segment_length[w, segment] - vehicle_length / 2
        ):
            found[total], following[total] = k, segment + 1
            total += 1
    return found[:total], following[:total]
