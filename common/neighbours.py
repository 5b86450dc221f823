"""The ego's neighbours in a world snapshot, as the safety layer (`planner`), the safety monitor and
the recording (`stack`) and the adaptive cruise's leaders (`controllers.leaders`) see them: each
other vehicle's footprint across the road, and the closest vehicle ahead and behind in a lane.

What a snapshot derives once (the footprints, every lane's neighbours) is kept in `DERIVED`, beside
the snapshot and not in it, for as long as the snapshot lives."""

from __future__ import annotations

import math
import weakref
from typing import Any

import numpy as np

from common.compiled import Kernel
from records import Neighbour, WorldState


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
        heading = _heading_to_the_lane(world)
        extent = np.abs(world.length[1:] * np.sin(heading)) + np.abs(world.width[1:] * np.cos(heading))
        kept["lateral_extent"] = extent
    return extent


def footprint_lateral_extent(world: WorldState) -> tuple[float, float]:
    """(lowest, highest) lateral coordinate [m] of the ego's footprint corners in the reference lane
    frame (its heading relative to the lane turns the rectangle)."""
    ego = world.ego_state()
    half = (
        float(world.length[0] * abs(math.sin(ego.heading)) + world.width[0] * abs(math.cos(ego.heading))) / 2
    )
    return ego.d - half, ego.d + half


def occupied_lanes(world: WorldState, extent: tuple[float, float] | None = None) -> tuple[int, ...]:
    """The lanes the ego's footprint reaches into (its `footprint_lateral_extent`, or `extent` when
    the caller has it already)."""
    low, high = footprint_lateral_extent(world) if extent is None else extent
    return tuple(
        lane
        for lane, centre in enumerate(world.lane_offsets.tolist())
        if reaches_lane(low, high, centre, world.lane_width)
    )


def reaches_lane(low: float, high: float, centre: float, lane_width: float) -> bool:
    """Whether a footprint spanning [`low`, `high`] across the road [m] reaches into the lane
    centred at `centre` (the batch compiles this same function: `stack.batch.kernels`)."""
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
    return world.speed[1:] * np.sin(_heading_to_the_lane(world)) * horizon_s


def _heading_to_the_lane(world: WorldState) -> np.ndarray:
    """Each other vehicle's heading relative to the lane at the ego [rad]."""
    return world.heading[1:] - world.lanes[0].heading_at(float(world.s[0]))


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
