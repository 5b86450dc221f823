"""The tracker's compiled entry points: `track_world` (one world, what `perception.tracking.Tracker`
calls), `track_worlds` (each world of a batch around the same law, `perception.tracking_law.
track_frame`) and `report_worlds` (the batch's report of each world's confirmed tracks)."""

from __future__ import annotations

import numpy as np
from numba import njit

from common.compiled import Kernel
from perception.tracking_law import (
    Measured,
    MeasuredWorlds,
    TrackerLaw,
    Tracks,
    confirmed_tracks,
    track_frame,
    tracked_rows,
)


@Kernel
def track_world(
    law: TrackerLaw,
    tracks: Tracks,
    found: Measured,
    position_variance: float,
    dt: float,
    lane_offsets: np.ndarray,
    lanes_count: int,
    lane_heading: float,
    slots_out: np.ndarray,
    lane_out: np.ndarray,
    rows_out: np.ndarray,
) -> int:  # pragma: no cover - compiled; covered through perception.tracking.Tracker
    """`track_frame`, `confirmed_tracks` and `tracked_rows` on one world: what the per-world
    tracker calls."""
    track_frame(law, tracks, found, position_variance, dt)
    count = confirmed_tracks(tracks, lane_offsets, lanes_count, slots_out, lane_out)
    tracked_rows(tracks, slots_out, count, lane_heading, rows_out)
    return count


_track_frame = njit(cache=True, nogil=True, inline="always")(track_frame)
_confirmed_tracks = njit(cache=True, nogil=True, inline="always")(confirmed_tracks)
_tracked_rows = njit(cache=True, nogil=True, inline="always")(tracked_rows)


@Kernel
def track_worlds(
    law: TrackerLaw,
    tracks: Tracks,
    found: MeasuredWorlds,
    position_variance: np.ndarray,
    dt: float,
    worlds: np.ndarray,
    lane_offsets: np.ndarray,
    lanes_count: np.ndarray,
    lane_heading: np.ndarray,
    slots_out: np.ndarray,
    lane_out: np.ndarray,
    rows_out: np.ndarray,
    counts_out: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through perception.tracking.TrackerBatch
    """`track_world` on each world flagged in `worlds` (its rows of `tracks` and `found`, the
    arrays' first axis the world's); its confirmed tracks' count into `counts_out`."""
    for w in range(len(worlds)):
        if not worlds[w]:
            continue
        one = Tracks(
            tracks.state[w],
            tracks.covariance[w],
            tracks.hits[w],
            tracks.age[w],
            tracks.misses[w],
            tracks.status[w],
            tracks.ident[w],
            tracks.size[w],
            tracks.next_ident[w],
        )
        measured = Measured(
            found.rows[w],
            found.s[w],
            found.d[w],
            found.speed[w],
            found.lateral_speed[w],
            found.length[w],
            found.width[w],
        )
        _track_frame(law, one, measured, position_variance[w], dt)
        counts_out[w] = _confirmed_tracks(one, lane_offsets[w], lanes_count[w], slots_out[w], lane_out[w])
        _tracked_rows(one, slots_out[w], counts_out[w], lane_heading[w], rows_out[w])


@Kernel
def report_worlds(
    tracked: np.ndarray,
    counts: np.ndarray,
    slots: np.ndarray,
    lanes: np.ndarray,
    rows: np.ndarray,
    detected: tuple[np.ndarray, ...],
    detected_lane: np.ndarray,
    out: tuple[np.ndarray, ...],
    out_lane: np.ndarray,
    out_slot: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through perception.tracking.TrackerBatch
    """What every world reports (`TrackerBatch.update`): into `out` (s, d, speed, heading, length,
    width, each (worlds, columns)), `out_lane` and `out_slot` (the track slot of each row, -1
    none), a tracked world's ego row then its `counts` confirmed tracks (`slots`, `lanes`, `rows`
    of `track_worlds`), zeros to column `columns_tracked` = 1 + the most tracks of any world and
    the detections beyond; an untracked world's `detected` rows (s, d, speed, heading, length,
    width) and `detected_lane`."""
    fields = ((0, 0), (1, 1), (2, 4), (3, 5), (4, 6), (5, 7))
    columns_tracked = 1 + counts.max() if len(counts) else 1
    for w in range(len(tracked)):
        for c in range(detected_lane.shape[1]):
            out_lane[w, c] = detected_lane[w, c]
        for f in range(len(detected)):
            for c in range(detected[f].shape[1]):
                out[f][w, c] = detected[f][w, c]
        if not tracked[w]:
            continue
        for c in range(1, columns_tracked):
            k = c - 1
            live = k < counts[w]
            out_lane[w, c] = lanes[w, k] if live else 0
            out_slot[w, c] = slots[w, k] if live else -1
            for f, column in fields:
                out[f][w, c] = rows[w, k, column] if live else 0.0
