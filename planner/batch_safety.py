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

from planner.safety import SafetyConfig
from records import N_ACTIONS
from records.batch import WorldBatch
from records.compiled import Kernel


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
    relative_heading = perceived.heading - perceived.lane_heading[:, None]
    extent = np.abs(perceived.length * np.sin(relative_heading)) + np.abs(
        perceived.width * np.cos(relative_heading)
    )
    reach = (perceived.lane_width + extent) / 2
    permitted = np.zeros((perceived.worlds, N_ACTIONS), dtype=np.float32)
    _permitted(
        permitted,
        perceived.columns(),
        reach,
        np.asarray(lane, dtype=np.int64),
        np.asarray(changing, dtype=np.bool_),
        np.asarray(speed, dtype=np.float64),
        min_speed,
        config.enabled,
        config.min_gap_m,
        config.front_time_gap_s,
        config.rear_time_gap_s,
        config.min_ttc_s,
    )
    return permitted


@njit(cache=True, nogil=True, inline="always")
def _clear(gap: float, min_gap: float, closing: float, min_ttc: float) -> bool:  # pragma: no cover - compiled
    """`planner.safety`'s `_clear`: the gap [m] is at least `min_gap` and the time to collision at
    `closing` [m/s] (infinite when not closing) at least `min_ttc` [s]."""
    ttc = np.inf if closing <= 0 else max(gap, 0.0) / closing
    return gap >= min_gap and ttc >= min_ttc


@Kernel
def _permitted(
    out: np.ndarray,
    columns: tuple[np.ndarray, ...],
    reach: np.ndarray,
    lane: np.ndarray,
    changing: np.ndarray,
    true_speed: np.ndarray,
    min_speed: float,
    enabled: bool,
    min_gap: float,
    front_time_gap: float,
    rear_time_gap: float,
    min_ttc: float,
) -> None:  # pragma: no cover - compiled; covered through permitted_batch
    count, s, d, speed, length, _, _, lanes_count, lane_offsets = columns
    for w in range(out.shape[0]):
        out[w, 1] = 1.0
        if changing[w] or true_speed[w] < min_speed:
            continue
        ego_speed = speed[w, 0]
        for command in (0, 2):
            target = lane[w] + command - 1
            if not enabled:
                out[w, command] = 1.0
                continue
            if target < 0 or target >= lanes_count[w]:
                continue
            ahead, behind = -1, -1
            best_ahead, best_behind = np.inf, np.inf
            for v in range(1, count[w]):
                if not abs(d[w, v] - lane_offsets[w, target]) < reach[w, v]:
                    continue
                rel = s[w, v] - s[w, 0]
                if rel > 0:
                    if ahead < 0 or abs(rel) < best_ahead:
                        ahead, best_ahead = v, abs(rel)
                elif behind < 0 or abs(rel) < best_behind:
                    behind, best_behind = v, abs(rel)
            safe = True
            if ahead >= 0:
                gap = abs(s[w, ahead] - s[w, 0]) - (length[w, ahead] + length[w, 0]) / 2
                needed = max(min_gap, front_time_gap * ego_speed)
                safe = _clear(gap, needed, ego_speed - speed[w, ahead], min_ttc)
            if safe and behind >= 0:
                gap = abs(s[w, behind] - s[w, 0]) - (length[w, behind] + length[w, 0]) / 2
                needed = max(min_gap, rear_time_gap * speed[w, behind])
                safe = _clear(gap, needed, speed[w, behind] - ego_speed, min_ttc)
            if safe:
                out[w, command] = 1.0
