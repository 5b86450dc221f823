"""The tracker's compiled entry points: `track_world` (one world, what `perception.tracking.Tracker`
calls), `track_worlds` (each world of a batch around the same law, `perception.tracking_law.
track_frame`) and `report_worlds` (the batch's report of each world's confirmed tracks).

`track_world` takes its settings, tracks and detections as plain arguments (numba's dispatcher
types a named tuple in about 2 µs, a plain array in 0.1-0.2 µs, once a frame per world) and writes
the whole tracked world into two flat buffers (`WORLD_FLOATS`, `WORLD_INTEGERS` columns of each
field), which `Tracker.update` only slices."""

from __future__ import annotations

import numpy as np
from numba import njit
from numba.extending import register_jitable

from common.compiled import Kernel
from perception.track_records import ROW_FIELDS, Measured, MeasuredWorlds, TrackerLaw, Tracks
from perception.tracking_law import confirmed_tracks, track_frame, tracked_rows

WORLD_FLOATS = 10
"""Float columns a tracked world row takes in `track_world`'s `floats_out`: position (2), velocity
(2), then heading, speed, length, width, s, d; each field a block of `columns` values (pairs
(columns, 2)), so a field's first rows are one contiguous slice."""
WORLD_INTEGERS = 2
"""Integer blocks of `track_world`'s `integers_out`: ids, then lanes."""


@Kernel
def track_world(
    confirm_hits: int,
    confirm_frames: int,
    coast_frames: int,
    gate: float,
    longitudinal_acceleration: float,
    lateral_acceleration: float,
    speed_variance: float,
    state: np.ndarray,
    covariance: np.ndarray,
    hits: np.ndarray,
    age: np.ndarray,
    misses: np.ndarray,
    status: np.ndarray,
    ident: np.ndarray,
    box: np.ndarray,
    next_ident: np.ndarray,
    rows: int,
    s: np.ndarray,
    d: np.ndarray,
    speed: np.ndarray,
    lateral_speed: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    heading: np.ndarray,
    position_variance: float,
    dt: float,
    lane_offsets: np.ndarray,
    lanes_count: int,
    lane_heading: float,
    ego_id: np.ndarray,
    ego_lane: np.ndarray,
    ego_position: np.ndarray,
    ego_velocity: np.ndarray,
    ego_heading: np.ndarray,
    ego_speed: np.ndarray,
    floats_out: np.ndarray,
    integers_out: np.ndarray,
    work_integers: np.ndarray,
    work_floats: np.ndarray,
) -> int:  # pragma: no cover - compiled; covered through perception.tracking.Tracker
    """`track_frame` on one world (the fields of `TrackerLaw`, `Tracks` and `Measured`, in order),
    then its tracked world into `floats_out` and `integers_out` (`WORLD_FLOATS` and
    `WORLD_INTEGERS` blocks of `columns` = len(floats_out) // WORLD_FLOATS): row 0 the ego
    (row 0 of `ego_*`, the detected world's ids, lane, position, velocity, heading, speed, and of
    `s`, `d`, `length`, `width`), then the confirmed tracks in slot order (`confirmed_tracks`,
    `tracked_rows`), the frame's work in `work_integers` and `work_floats` (`work_size`). Returns
    how many tracks are confirmed."""
    law = TrackerLaw(
        confirm_hits,
        confirm_frames,
        coast_frames,
        gate,
        longitudinal_acceleration,
        lateral_acceleration,
        speed_variance,
    )
    tracks = Tracks(state, covariance, hits, age, misses, status, ident, box, next_ident)
    found = Measured(rows, s, d, speed, lateral_speed, length, width, heading)
    track_frame(law, tracks, found, position_variance, dt, work_integers, work_floats)
    slots = np.empty(len(status), dtype=np.int64)
    lanes = np.empty(len(status), dtype=np.int64)
    count = confirmed_tracks(tracks, lane_offsets, lanes_count, slots, lanes)
    tracked = np.empty((count, ROW_FIELDS))
    tracked_rows(tracks, slots, count, lane_heading, tracked)
    columns = len(floats_out) // WORLD_FLOATS
    integers_out[0], integers_out[columns] = ego_id[0], ego_lane[0]
    for pair in range(2):
        floats_out[pair] = ego_position[0, pair]
        floats_out[2 * columns + pair] = ego_velocity[0, pair]
    ego_row = (ego_heading[0], ego_speed[0], length[0], width[0], s[0], d[0])
    for f in range(6):
        floats_out[(4 + f) * columns] = ego_row[f]
    for k in range(count):
        c = k + 1
        integers_out[c], integers_out[columns + c] = ident[slots[k]], lanes[k]
        _write_row(floats_out, columns, c, tracked[k])
    return count


@register_jitable
def _write_row(floats_out: np.ndarray, columns: int, c: int, row: np.ndarray) -> None:
    """Row `c` of `track_world`'s float blocks from a `tracked_rows` row: position (s, d),
    velocity, heading, speed, length, width, s, d."""
    floats_out[2 * c], floats_out[2 * c + 1] = row[0], row[1]
    floats_out[2 * columns + 2 * c], floats_out[2 * columns + 2 * c + 1] = row[2], row[3]
    floats_out[4 * columns + c], floats_out[5 * columns + c] = row[5], row[4]
    floats_out[6 * columns + c], floats_out[7 * columns + c] = row[6], row[7]
    floats_out[8 * columns + c], floats_out[9 * columns + c] = row[0], row[1]


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
    work_integers: np.ndarray,
    work_floats: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through perception.tracking.TrackerBatch
    """`track_world` on each world flagged in `worlds` (its rows of `tracks` and `found`, the
    arrays' first axis the world's); its confirmed tracks' count into `counts_out`. The worlds
    share the work buffers (`work_size` for the widest), one after the other."""
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
            tracks.box[w],
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
            found.heading[w],
        )
        _track_frame(law, one, measured, position_variance[w], dt, work_integers, work_floats)
        counts_out[w] = _confirmed_tracks(one, lane_offsets[w], lanes_count[w], slots_out[w], lane_out[w])
        _tracked_rows(one, slots_out[w], counts_out[w], lane_heading[w], rows_out[w])


REPORTED_ROW_COLUMNS = (0, 1, 4, 5, 6, 7)
"""The `tracked_rows` column of each field `report_worlds` reports: s, d, speed, heading, length,
width."""


@Kernel
def report_worlds(
    tracked: np.ndarray,
    counts: np.ndarray,
    slots: np.ndarray,
    lanes: np.ndarray,
    rows: np.ndarray,
    detected: tuple[np.ndarray, ...],
    detected_lane: np.ndarray,
    out: np.ndarray,
    out_lane: np.ndarray,
    out_slot: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through perception.tracking.TrackerBatch
    """What every world reports (`TrackerBatch.update`), every element of `out` (s, d, speed,
    heading, length, width: (6, worlds, columns)), `out_lane` and `out_slot` (the track slot of
    each row, -1 none) written: a tracked world's ego row then its `counts` confirmed tracks
    (`slots`, `lanes`, `rows` of `track_worlds`), zeros to column `columns_tracked` = 1 + the most
    tracks of any world, then the detections beyond; an untracked world's `detected` rows (s, d,
    speed, heading, length, width) and `detected_lane`; zeros past the detections."""
    columns_tracked = 1 + counts.max() if len(counts) else 1
    found, columns = detected_lane.shape[1], out_lane.shape[1]
    for w in range(len(tracked)):
        tracks = columns_tracked if tracked[w] else 1
        for c in range(columns):
            k = c - 1
            if c < tracks and 0 <= k < counts[w]:
                for f in range(len(REPORTED_ROW_COLUMNS)):
                    out[f, w, c] = rows[w, k, REPORTED_ROW_COLUMNS[f]]
                out_lane[w, c], out_slot[w, c] = lanes[w, k], slots[w, k]
                continue
            shown = c < found and (c == 0 or c >= tracks)
            for f in range(len(REPORTED_ROW_COLUMNS)):
                out[f, w, c] = detected[f][w, c] if shown else 0.0
            out_lane[w, c], out_slot[w, c] = (detected_lane[w, c] if shown else 0), -1
