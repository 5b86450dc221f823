"""The safety layer's verdicts for many worlds at once: `ClosedLoop.permitted()` of every world of a
`WorldBatch` in one compiled pass, to the same answers.

Per world and side lane: the nearest vehicle ahead and behind among those reaching into the lane
(`WorldState.neighbours`: centre within half a lane plus half the vehicle's turned footprint), then
the gap rule of `planner.safety.unsafe_neighbours` with its strict time gaps. The footprints' sines
and cosines run in numpy over the whole batch, as the per-world snapshot runs them over one world;
the rest is comparisons, sums, products and divisions, numpy's bits in numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from common.compiled import Kernel
from planner.safety import SafetyConfig
from records import N_ACTIONS
from records.batch import WorldBatch


def lateral_extents(batch: WorldBatch) -> np.ndarray:
    """(worlds, vehicles): each vehicle's footprint width across the road [m], its rectangle
    turned by its heading to the lane (`common.neighbours.lateral_extent`, over the whole batch)."""
    relative_heading = _headings_to_the_lane(batch)
    return np.abs(batch.length * np.sin(relative_heading)) + np.abs(batch.width * np.cos(relative_heading))


def lateral_drifts(batch: WorldBatch, horizon_s: float) -> np.ndarray:
    """(worlds, vehicles): how far each vehicle moves across the road in `horizon_s` [s] at its
    present lateral speed [m] (`common.neighbours.lateral_drift`, over the whole batch)."""
    return batch.speed * np.sin(_headings_to_the_lane(batch)) * horizon_s


def _headings_to_the_lane(batch: WorldBatch) -> np.ndarray:
    """(worlds, vehicles): each vehicle's heading relative to the lane at its world's ego [rad]."""
    return batch.heading - batch.lane_heading[:, None]


def permitted_batch(
    config: SafetyConfig,
    perceived: WorldBatch,
    lane: np.ndarray,
    changing: np.ndarray,
    speed: np.ndarray,
    min_speed: float,
) -> np.ndarray:
    """(worlds, N_ACTIONS) float32, 1 where the loop would carry the command out: STAY always; a
    lane change when the maneuver of that world keeps its `lane` (not `changing`), its ego's true
    `speed` [m/s] is at least `min_speed` and the safety layer passes the gap it leads into, on
    what the sensor reports (`perceived`)."""
    reach = (perceived.lane_width + lateral_extents(perceived)) / 2
    permitted = np.zeros((perceived.worlds, N_ACTIONS), dtype=np.float32)
    _permitted(
        permitted,
        perceived.columns(),
        reach,
        np.asarray(lane, dtype=np.int64),
        np.asarray(changing, dtype=np.bool_),
        np.asarray(speed, dtype=np.float64),
        min_speed,
        safety_settings(config),
    )
    return permitted


@njit(cache=True, nogil=True, inline="always")
def _clear(gap: float, min_gap: float, closing: float, min_ttc: float) -> bool:  # pragma: no cover - compiled
    """`planner.safety`'s `_clear`: the gap [m] is at least `min_gap` and the time to collision at
    `closing` [m/s] (infinite when not closing) at least `min_ttc` [s]."""
    ttc = np.inf if closing <= 0 else max(gap, 0.0) / closing
    return gap >= min_gap and ttc >= min_ttc


@njit(cache=True, nogil=True)
def lane_is_safe(
    n: int,
    s: np.ndarray,
    d: np.ndarray,
    drift: np.ndarray,
    speed: np.ndarray,
    length: np.ndarray,
    reach: np.ndarray,
    centre: float,
    min_gap: float,
    min_ttc: float,
    front_time_gap: float,
    rear_time_gap: float,
) -> bool:  # pragma: no cover - compiled
    """`SafetyLayer.gap_is_safe` of one world's `n` vehicles (row 0 the ego, each reaching `reach`
    [m] across the road from its centre) for the lane centred at `centre` [m]: the nearest vehicle
    ahead and behind (the first on ties) leave `min_gap` [m], or the time gaps when they are
    non-zero (the strict rule), and `min_ttc` [s]. A vehicle is in the lane when it reaches into it
    anywhere between d and d + `drift` [m] (`common.neighbours.scanned_neighbours`; zeros: now)."""
    ahead, behind = -1, -1
    best_ahead, best_behind = np.inf, np.inf
    for v in range(1, n):
        low, high = min(d[v], d[v] + drift[v]), max(d[v], d[v] + drift[v])
        across = 0.0 if low <= centre <= high else min(abs(low - centre), abs(high - centre))
        if not across < reach[v]:
            continue
        rel = s[v] - s[0]
        if rel > 0:
            if ahead < 0 or abs(rel) < best_ahead:
                ahead, best_ahead = v, abs(rel)
        elif behind < 0 or abs(rel) < best_behind:
            behind, best_behind = v, abs(rel)
    ego_speed = speed[0]
    if ahead >= 0:
        gap = abs(s[ahead] - s[0]) - (length[ahead] + length[0]) / 2
        if not _clear(gap, max(min_gap, front_time_gap * ego_speed), ego_speed - speed[ahead], min_ttc):
            return False
    if behind >= 0:
        gap = abs(s[behind] - s[0]) - (length[behind] + length[0]) / 2
        needed = max(min_gap, rear_time_gap * speed[behind])
        if not _clear(gap, needed, speed[behind] - ego_speed, min_ttc):
            return False
    return True


@njit(cache=True, nogil=True)
def change_is_safe(
    n: int,
    s: np.ndarray,
    d: np.ndarray,
    now: np.ndarray,
    speed: np.ndarray,
    length: np.ndarray,
    reach: np.ndarray,
    offsets: np.ndarray,
    lanes_count: int,
    lane: int,
    goal: int,
    safety: np.ndarray,
) -> bool:  # pragma: no cover - compiled
    """`SafetyLayer.permits` of one world's change from `lane` to `goal`: on the road, the strict
    gap rule in `goal` (`safety`: enabled, min gap [m], min TTC [s], front and rear time gaps [s],
    ..., `safety[7]` the far-lane gap [m], -inf: none) and, in the lane beyond it, no vehicle
    nearer than the far-lane gap bumper to bumper. `now`: zeros, one a vehicle."""
    if not 0 <= goal < lanes_count:
        return False
    if not lane_is_safe(
        n, s, d, now, speed, length, reach, offsets[goal], safety[1], safety[2], safety[3], safety[4]
    ):
        return False
    beyond = 2 * goal - lane
    if safety[7] == -np.inf or not 0 <= beyond < lanes_count:
        return True
    return lane_is_safe(n, s, d, now, speed, length, reach, offsets[beyond], safety[7], 0.0, 0.0, 0.0)


def safety_settings(config: SafetyConfig) -> np.ndarray:
    """The safety layer's numbers as the compiled passes take them (`change_is_safe`; the abort
    gap [m] and TTC [s] at 5 and 6)."""
    far = -np.inf if config.far_lane_gap_m is None else config.far_lane_gap_m
    return np.array(
        [
            float(config.enabled),
            config.min_gap_m,
            config.min_ttc_s,
            config.front_time_gap_s,
            config.rear_time_gap_s,
            config.abort_gap_m,
            config.abort_ttc_s,
            far,
        ]
    )


@Kernel
def _permitted(
    out: np.ndarray,
    columns: tuple[np.ndarray, ...],
    reach: np.ndarray,
    lane: np.ndarray,
    changing: np.ndarray,
    true_speed: np.ndarray,
    min_speed: float,
    safety: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through permitted_batch
    count, s, d, speed, length, _, _, lanes_count, lane_offsets = columns
    now = np.zeros(s.shape[1])
    for w in range(out.shape[0]):
        out[w, 1] = 1.0
        if changing[w] or true_speed[w] < min_speed:
            continue
        for command in (0, 2):
            target = lane[w] + command - 1
            if safety[0] == 0.0:
                out[w, command] = 1.0
            elif change_is_safe(
                count[w], s[w], d[w], now, speed[w], length[w], reach[w], lane_offsets[w], lanes_count[w],
                lane[w], target, safety,
            ):  # fmt: skip
                out[w, command] = 1.0
