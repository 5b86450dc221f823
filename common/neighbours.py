"""The ego's neighbours in a world snapshot, as the safety layer (`planner`), the safety monitor and
the recording (`stack`) and the adaptive cruise's leaders (`controllers.leaders`) see them: each
other vehicle's footprint across the road, and the closest vehicle ahead and behind in a lane.

What a snapshot derives once (the footprints, every lane's neighbours) is kept in `DERIVED`, beside
the snapshot and not in it, for as long as the snapshot lives. The laws that compiled code runs too
(`reaches_lane`, `footprint_across`, `nearest_in_lane`) are plain functions that numba compiles
where a compiled caller calls them; `lateral_extents` and `lateral_drifts` are the footprints of a
whole `WorldBatch`."""

from __future__ import annotations

import math
import weakref
from typing import Any, NamedTuple

import numpy as np
from numba.extending import register_jitable

from common.compiled import Kernel
from records import Neighbour, WorldState
from records.batch import WorldBatch

WANDERING_M = 0.375
"""R157's lateral wandering zone: how far a vehicle may drift from its lane centre unnoticed [m]."""


class PerSnapshot:
    """Values derived from a `WorldState` once, by the snapshot's id while it lives. Kept beside the
    record, not in it, so its `__dict__` stays its fields (`type(w)(**w.__dict__)`,
    `dataclasses.replace`, pickling and copies see none of it); a snapshot, like every record, is
    never changed once made, so what was derived from it stays true."""

    def __init__(self) -> None:
        self.kept: dict[int, dict[str, Any]] = {}

    def of(self, world: WorldState) -> dict[str, Any]:
        """The values kept for `world` (empty at first), dropped when `world` is collected."""
        kept = self.kept.get(id(world))
        if kept is None:
            kept = self.kept[id(world)] = {}
            weakref.finalize(world, self.kept.pop, id(world), None)
        return kept


DERIVED = PerSnapshot()


def lateral_extent(world: WorldState) -> np.ndarray:
    """Each other vehicle's footprint width across the road [m]: its rectangle turned by its
    heading relative to the lane at the ego (a car nosing into a lane at 30 deg reaches 2.4 m
    further across than its width says); computed once per snapshot (`leaders`, every lane's
    neighbours and each merging car's check read it)."""
    kept = DERIVED.of(world)
    extent = kept.get("lateral_extent")
    if extent is None:
        extent = kept["lateral_extent"] = turned_width(
            world.length[1:], world.width[1:], _heading_to_the_lane(world)
        )
    return extent


def lateral_extents(batch: WorldBatch) -> np.ndarray:
    """(worlds, vehicles): `lateral_extent` of every vehicle of every world of `batch` [m]."""
    return turned_width(batch.length, batch.width, _headings_to_the_lane(batch))


def turned_width(length: np.ndarray, width: np.ndarray, heading_to_lane: np.ndarray) -> np.ndarray:
    """Footprint widths across the road [m] of rectangles `length` by `width` [m] turned by
    `heading_to_lane` [rad]."""
    return np.abs(length * np.sin(heading_to_lane)) + np.abs(width * np.cos(heading_to_lane))


class VehicleRows(NamedTuple):
    """One world's vehicles as the compiled laws take them, a row each, row 0 the ego: `vehicles`
    of them, centres `s` and `d` [m] (in lane 0's frame), `speed` [m/s], `length` [m], how far each
    reaches across the road from its centre into a lane, `reach` [m] (half a lane plus half its
    `lateral_extent`; the ego's never read), and how far it is taken to drift across, `drift` [m]
    (zeros: where it is now)."""

    vehicles: int
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    reach: np.ndarray
    drift: np.ndarray


def vehicle_rows(world: WorldState) -> VehicleRows:
    """`world`'s `VehicleRows`, where they are now; made once per snapshot."""
    kept = DERIVED.of(world)
    rows = kept.get("vehicle_rows")
    if rows is None:
        reach = np.concatenate(([0.0], (world.lane_width + lateral_extent(world)) / 2))
        still = np.zeros(world.count)
        rows = kept["vehicle_rows"] = VehicleRows(
            world.count, world.s, world.d, world.speed, world.length, reach, still
        )
    return rows


def footprint_lateral_extent(world: WorldState) -> tuple[float, float]:
    """(lowest, highest) lateral coordinate [m] of the ego's footprint corners in the reference lane
    frame (its heading relative to the lane turns the rectangle)."""
    ego = world.ego_state()
    return footprint_across(ego.d, world.length[0], world.width[0], ego.heading)


@register_jitable
def footprint_across(d: float, length: float, width: float, heading_to_lane: float) -> tuple[float, float]:
    """(lowest, highest) lateral coordinate [m] of the corners of a `length` by `width` [m]
    footprint centred at `d` [m], turned by `heading_to_lane` [rad]."""
    half = float(length * abs(math.sin(heading_to_lane)) + width * abs(math.cos(heading_to_lane))) / 2
    return d - half, d + half


def occupied_lanes(world: WorldState, extent: tuple[float, float] | None = None) -> tuple[int, ...]:
    """The lanes the ego's footprint reaches into (its `footprint_lateral_extent`, or `extent` when
    the caller has it already)."""
    low, high = footprint_lateral_extent(world) if extent is None else extent
    return tuple(
        lane
        for lane, centre in enumerate(world.lane_offsets.tolist())
        if reaches_lane(low, high, centre, world.lane_width)
    )


@register_jitable
def lane_beyond(lane: int, target: int, lanes_count: int) -> int:
    """The lane beyond `target` seen from `lane` (a change from `lane` to `target`), -1 when the
    road has none."""
    beyond = 2 * target - lane
    return beyond if 0 <= beyond < lanes_count else -1


@register_jitable
def reaches_lane(low: float, high: float, centre: float, lane_width: float) -> bool:
    """Whether a footprint spanning [`low`, `high`] across the road [m] reaches into the lane
    centred at `centre` (the batch compiles this same function: `stack.batch.loop_kernels`)."""
    return low < centre + lane_width / 2 and high > centre - lane_width / 2


def neighbours(world: WorldState, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
    """(closest vehicle ahead, closest vehicle behind) of the ego among those whose footprint
    (`lateral_extent`) reaches into `lane`; ahead/behind by centre position along the road.

    Every lane's rows are found at once, on the first query, and kept for the snapshot while it
    lives."""
    kept = DERIVED.of(world)
    cache = kept.get("neighbours")
    if cache is None:
        cache = kept["neighbours"] = {}
    found = cache.get(lane)
    if found is None:
        found = cache[lane] = _neighbours_from_table(world, lane)
    return found


def _neighbours_from_table(world: WorldState, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
    kept = DERIVED.of(world)
    if "table" not in kept:
        kept["table"] = _neighbour_rows(world)
    table = kept["table"]
    lanes = len(world.lane_offsets)
    if table is None or not -lanes <= lane < lanes:
        return scanned_neighbours(world, lane)
    rows, found, gap, speed, ids = table
    ahead, behind = (
        Neighbour(gap[row], speed[row], ids[row]) if found[side][lane] else None
        for side in (0, 1)
        for row in (rows[side][lane],)
    )
    return ahead, behind


def _neighbour_rows(
    world: WorldState,
) -> tuple[list[list[int]], list[list[bool]], list[float], list[float], list[int]] | None:
    """For each side (ahead, behind) and lane, the row (among the others) `scanned_neighbours`
    picks and whether there is one, with every other vehicle's gap, speed and id; every lane in
    one compiled pass (None where a distance is infinite, then `scanned_neighbours` answers)."""
    if world.count < 2:
        return None
    rel_s = world.s[1:] - world.s[0]
    reach = (world.lane_width + lateral_extent(world)) / 2
    nearest = _nearest_in_lanes(rel_s, np.ascontiguousarray(world.d[1:]), world.lane_offsets, reach)
    if nearest is None:
        return None
    rows, found = nearest
    gap = np.abs(rel_s) - (world.length[1:] + world.length[0]) / 2
    return rows.tolist(), found.tolist(), gap.tolist(), world.speed[1:].tolist(), world.ids[1:].tolist()


def lateral_drift(world: WorldState, horizon_s: float) -> np.ndarray:
    """How far each other vehicle moves across the road in `horizon_s` [s] at its present lateral
    speed (its speed times the sine of its heading to the lane at the ego) [m]; positive towards
    higher d."""
    return drift_across(world.speed[1:], _heading_to_the_lane(world), horizon_s)


def lateral_drifts(batch: WorldBatch, horizon_s: float) -> np.ndarray:
    """(worlds, vehicles): `lateral_drift` of every vehicle of every world of `batch` [m]."""
    return drift_across(batch.speed, _headings_to_the_lane(batch), horizon_s)


def drift_across(speed: np.ndarray, heading_to_lane: np.ndarray, horizon_s: float) -> np.ndarray:
    """How far vehicles at `speed` [m/s] heading `heading_to_lane` [rad] move across the road in
    `horizon_s` [s] [m]."""
    return speed * np.sin(heading_to_lane) * horizon_s


def _heading_to_the_lane(world: WorldState) -> np.ndarray:
    """Each other vehicle's heading relative to the lane at the ego [rad]."""
    return world.heading[1:] - world.lanes[0].heading_at(float(world.s[0]))


def _headings_to_the_lane(batch: WorldBatch) -> np.ndarray:
    """(worlds, vehicles): each vehicle's heading relative to the lane at its world's ego [rad]."""
    return batch.heading - batch.lane_heading[:, None]


@register_jitable
def between_lanes(d: float, offsets: np.ndarray) -> bool:
    """Whether a centre at `d` [m] is farther than R157's wandering zone (`WANDERING_M`) from every
    lane centre of `offsets` [m]: the vehicle is crossing from one lane to another."""
    nearest = math.inf
    for centre in offsets:
        nearest = min(nearest, abs(d - centre))
    return nearest > WANDERING_M


@register_jitable
def swept_distance(d: float, drift: float, centre: float) -> float:
    """How far across the road [m] a centre moving from `d` to `d + drift` [m] comes to `centre`
    [m] on its way (0 when it crosses it)."""
    low, high = min(d, d + drift), max(d, d + drift)
    return 0.0 if low <= centre <= high else min(abs(low - centre), abs(high - centre))


@register_jitable
def nearest_in_lane(rows: VehicleRows, centre: float) -> tuple[int, int]:
    """(row ahead, row behind; -1: none) of the vehicles nearest the ego along the road (the first on
    ties) among one world's `rows` that reach into the lane centred at `centre` [m], anywhere
    between d and d + drift. Ahead: s above the ego's; behind: at or below it."""
    s, d, drift, reach = rows.s, rows.d, rows.drift, rows.reach
    ahead, behind = -1, -1
    best_ahead, best_behind = math.inf, math.inf
    for v in range(1, rows.vehicles):
        if not swept_distance(d[v], drift[v], centre) < reach[v]:
            continue
        rel = s[v] - s[0]
        if rel > 0:
            if ahead < 0 or abs(rel) < best_ahead:
                ahead, best_ahead = v, abs(rel)
        elif rel <= 0 and (behind < 0 or abs(rel) < best_behind):
            behind, best_behind = v, abs(rel)
    return ahead, behind


def scanned_neighbours(
    world: WorldState, lane: int, drift: np.ndarray | None = None
) -> tuple[Neighbour | None, Neighbour | None]:
    """`neighbours` of one lane, found by scanning it alone (numpy, no kernel): what the compiled
    pass answers where a distance is infinite, and what it is tested against. With `drift`
    (`lateral_drift`), a vehicle also counts when its footprint reaches into the lane anywhere on
    its way from d to d + drift: a car about to cut in is a neighbour before it arrives."""
    rel_s = world.s[1:] - world.s[0]
    gap = np.abs(rel_s) - (world.length[1:] + world.length[0]) / 2
    reach = (world.lane_width + lateral_extent(world)) / 2
    centre, d = world.lane_offsets[lane], world.d[1:]
    if drift is None:
        in_lane = np.abs(d - centre) < reach
    else:
        low, high = np.minimum(d, d + drift), np.maximum(d, d + drift)
        across = np.minimum(np.abs(low - centre), np.abs(high - centre))
        in_lane = np.where((low <= centre) & (centre <= high), 0.0, across) < reach
    found: list[Neighbour | None] = []
    for side in (rel_s > 0, rel_s <= 0):
        candidates = np.flatnonzero(in_lane & side)
        if candidates.size:
            row = candidates[np.argmin(np.abs(rel_s[candidates]))]
            found.append(Neighbour(float(gap[row]), float(world.speed[row + 1]), int(world.ids[row + 1])))
        else:
            found.append(None)
    return found[0], found[1]


@Kernel
def _nearest_in_lanes(
    rel_s: np.ndarray, d: np.ndarray, lane_offsets: np.ndarray, reach: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:  # pragma: no cover - compiled; covered through neighbours
    """For each side (ahead: rel_s > 0, behind: rel_s <= 0) and lane, the row of the vehicle nearest
    the ego along the road (the first on ties) among those reaching into the lane (|d - offset| <
    reach), and whether there is one: vehicles at rel_s [m] along the road and d [m] across it,
    each reaching `reach` [m] from its centre; None if a distance is infinite. Comparisons only."""
    lanes, count = lane_offsets.shape[0], rel_s.shape[0]
    rows = np.zeros((2, lanes), dtype=np.int64)
    found = np.zeros((2, lanes), dtype=np.bool_)
    for k in range(count):
        if np.isinf(rel_s[k]):
            return None
    for lane in range(lanes):
        best = np.full(2, np.inf)
        for k in range(count):
            if not abs(d[k] - lane_offsets[lane]) < reach[k]:
                continue
            side = 0 if rel_s[k] > 0 else 1 if rel_s[k] <= 0 else -1
            if side >= 0 and (not found[side, lane] or abs(rel_s[k]) < best[side]):
                rows[side, lane], found[side, lane], best[side] = k, True, abs(rel_s[k])
    return rows, found
