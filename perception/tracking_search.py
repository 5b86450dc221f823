"""The tracker's search, part of its per-frame law (`perception.tracking_law.track_frame`): the
detections ordered along the road (`stable_order`) and bucketed (`fill_buckets`, `first_at_least`),
so each track checks only the detections within its gate's reach, and the gated candidates assigned
greedily, nearest first (`assign_greedy_into`). Plain functions numba compiles, for one world and a
batch alike."""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable


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
    (track, detection, cost): `assign_greedy_into` on fresh buffers."""
    assigned = np.empty(found, dtype=np.int64)
    assign_greedy_into(
        pair_track, pair_found, pair_cost, pairs, np.empty(tracks, dtype=np.int64),
        np.empty(found, dtype=np.int64), assigned, np.empty(pairs, dtype=np.int64), np.empty(pairs),
        np.empty(pairs), np.empty(pairs, dtype=np.int64),
    )  # fmt: skip
    return assigned


@register_jitable
def assign_greedy_into(
    pair_track: np.ndarray,
    pair_found: np.ndarray,
    pair_cost: np.ndarray,
    pairs: int,
    track_pairs: np.ndarray,
    found_pairs: np.ndarray,
    assigned: np.ndarray,
    contested: np.ndarray,
    contested_cost: np.ndarray,
    contested_sorted: np.ndarray,
    contested_order: np.ndarray,
) -> None:
    """The track each detection is assigned (-1: none) into `assigned` (one element a detection),
    from the `pairs` gated candidates (track, detection, cost): the cheapest pair first, then the
    cheapest left whose track and detection are both free (global nearest neighbour, greedy; ties
    to the earlier pair). A pair whose track and detection are in no other pair is taken whatever
    the order, so only the contested pairs are sorted (most tracks on a highway have one
    uncontested candidate). `track_pairs` (one element a track), `found_pairs` (a detection) and
    the `contested*` buffers (a pair) are work space. Written by hand because the batch compiles
    it: scipy's `linear_sum_assignment` cannot run inside numba. Inside the gate vehicles stand a
    car length apart and detections are metres apart at most, so the nearest pair is almost
    always the optimal assignment's; the tests check it against scipy's on such scenes."""
    track_pairs[:] = 0
    found_pairs[:] = 0
    for k in range(pairs):
        track_pairs[pair_track[k]] += 1
        found_pairs[pair_found[k]] += 1
    assigned[:] = -1
    count = 0
    for k in range(pairs):
        t, j = pair_track[k], pair_found[k]
        if track_pairs[t] == 1 and found_pairs[j] == 1:
            assigned[j] = t
        else:
            contested[count], contested_cost[count] = k, pair_cost[k]
            count += 1
    order = stable_order(contested_cost[:count], contested_sorted, contested_order)
    for i in order:
        k = contested[i]
        t, j = pair_track[k], pair_found[k]
        if track_pairs[t] < 0 or assigned[j] >= 0:
            continue
        track_pairs[t] = -1
        assigned[j] = t


@register_jitable
def stable_order(values: np.ndarray, ordered: np.ndarray, order: np.ndarray) -> np.ndarray:
    """The indices that sort `values` ascending, ties in their order (numpy's mergesort), into
    `order` (returned: its first `len(values)`), the sorted values into `ordered`: an insertion
    sort, as a sensor reports vehicles nearly in order along the road; past `len(values)` moves or
    on a NaN, numpy's mergesort (the same order)."""
    n = len(values)
    order = order[:n]
    for i in range(n):
        order[i] = i
    moves = 0
    for i in range(n):
        value, k = values[i], i
        while k > 0 and ordered[k - 1] > value:
            ordered[k], order[k] = ordered[k - 1], order[k - 1]
            k -= 1
            moves += 1
        ordered[k], order[k] = value, i
        if moves > n or value != value:
            order[:] = np.argsort(values, kind="mergesort")
            for m in range(n):
                ordered[m] = values[order[m]]
            return order
    return order


@register_jitable
def bucket(value: float, low: float, high: float, scale: float, buckets: int) -> int:
    """The bucket of `value` [m] among `buckets` over [`low`, `high`] (`scale` = buckets / (high -
    low)): the same or a higher one for a higher value, 0 below `low`, the last above `high`."""
    if not value > low:
        return 0
    if not value < high:
        return buckets - 1
    return int(min((value - low) * scale, buckets - 1))


@register_jitable
def fill_buckets(ordered: np.ndarray, finite: int, starts: np.ndarray) -> tuple[float, float, float]:
    """Bucket the first `finite` values of `ordered` (ascending): `finite` buckets over their span,
    `starts[b]` the first index whose bucket is b or higher (`starts[finite]` = `finite`). Returns
    (low, high, scale) for `bucket`."""
    if finite == 0:
        starts[0] = 0
        return 0.0, 0.0, 0.0
    low, high = ordered[0], ordered[finite - 1]
    scale = finite / (high - low) if high > low else 0.0
    k = 0
    for b in range(finite + 1):
        while k < finite and bucket(ordered[k], low, high, scale, finite) < b:
            k += 1
        starts[b] = k
    return low, high, scale


@register_jitable
def first_at_least(
    ordered: np.ndarray, finite: int, starts: np.ndarray, low: float, high: float, scale: float, value: float
) -> int:
    """The first index of the bucketed `ordered` (`fill_buckets`: `starts`, `low`, `high`,
    `scale`) whose value is not below `value` (`finite` if none, or if `value` is NaN): numpy's
    `searchsorted(side="left")` over the first `finite` values, from `value`'s bucket on (every
    value of a lower bucket is below it)."""
    if value != value or finite == 0:
        return finite
    k = starts[bucket(value, low, high, scale, finite)]
    while k < finite and ordered[k] < value:
        k += 1
    return k
