"""Drivers who weave: a vehicle that turned back in the middle of a lane change (its sideways motion
reversed while it was between lanes: a cut-in given up, a lane tried and left) may try again, and a
driver who does not see the ego tries again into its side. A careful driver does not close up
beside such a car: for `controller.weaver_wary_s` (`WARY_S`, 10 s) after its last weave the
cruise keeps its time gap to it while it is ahead in a lane next to the one the ego keeps or heads
for (`weavers_in_rows`), unless the ego passes it sooner than it could fall back behind it;
emergency braking waits until it does turn in, as for a car that may turn back
(`controllers.leaders.turning_back_in_rows`).

What is remembered of each vehicle is one law (`turned_back`), kept for one world by the maneuver
(`WeaveMemory`, a column per vehicle id) and for many by the batch (a column per memory slot), both
through `note_weaves`."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable

from common.neighbours import between_lanes
from controllers.passing import FoundLeaders, LeaderRows, is_listed, passes_sooner_than_falls_back

WEAVE_MPS = 0.3
"""Sideways speed below which a vehicle between lanes is not seen moving either way [m/s]."""
WARY_S = 10.0
"""How long after its last weave a vehicle is kept a time gap to [s]: `controller.weaver_wary_s`'s
default."""


@register_jitable
def turned_back(between: bool, sideways: float, moving: float) -> tuple[float, bool]:
    """One vehicle's weave memory over one tick: `between`, whether it is between lanes (farther
    than `WANDERING_M` from every lane centre, `common.neighbours.between_lanes`); `sideways`
    [m/s], its speed across the road; `moving`, the way it was moving across while between lanes
    (+1, -1; 0: not between lanes, or not seen moving). Returns the way to remember and whether it
    turned back now: it moves against `moving` while between lanes."""
    if not between:
        return 0.0, False
    if abs(sideways) < WEAVE_MPS:
        return moving, False
    way = math.copysign(1.0, sideways)
    return way, moving == -way


@register_jitable
def note_weaves(
    world: LeaderRows, time: float, columns: np.ndarray, moving: np.ndarray, weaved_at: np.ndarray
) -> None:
    """One tick of the weave memory of `world`'s vehicles at `time` [s]: row r's vehicle keeps its
    way across in `moving[columns[r]]` and the time it last turned back in `weaved_at[columns[r]]`
    [s] (`turned_back`); writes how long ago that was into `world.weaved_s` (row 0, the ego: inf)."""
    world.weaved_s[0] = math.inf
    for row in range(1, world.vehicles):
        between = between_lanes(world.d[row], world.lane_offsets)
        sideways = world.speed[row] * math.sin(world.heading_to_lane[row])
        column = columns[row]
        moving[column], back = turned_back(between, sideways, moving[column])
        if back:
            weaved_at[column] = time
        world.weaved_s[row] = time - weaved_at[column]


@register_jitable
def column_of(keys: np.ndarray, vehicle: int) -> int:
    """The column of the vehicle of id `vehicle` (>= 0) in the open-addressed table `keys` (-1: a
    free column), taken now if the vehicle is new; the table must have a free column."""
    column = vehicle % keys.size
    while keys[column] != vehicle and keys[column] != -1:
        column = (column + 1) % keys.size
    keys[column] = vehicle
    return column


class WeaveTable(NamedTuple):
    """One world's weave memory, a column per vehicle id (`column_of`): the ids, `keys` (-1: a free
    column), each one's way across, `moving`, and the time it last turned back, `weaved_at` [s]."""

    keys: np.ndarray
    moving: np.ndarray
    weaved_at: np.ndarray


@register_jitable
def note_weaves_by_id(world: LeaderRows, time: float, ids: np.ndarray, table: WeaveTable) -> None:
    """`note_weaves` with row r's memory in the column of `table` of its vehicle's id `ids[r]`."""
    columns = np.empty(world.vehicles, dtype=np.int64)
    for row in range(world.vehicles):
        columns[row] = column_of(table.keys, ids[row])
    note_weaves(world, time, columns, table.moving, table.weaved_at)


class WeaveMemory:
    """One world's weave memory (`note_weaves`), a column per vehicle id seen (`column_of`): what
    the batch keeps per memory slot."""

    def __init__(self, columns: int = 256) -> None:
        self.keys = np.full(columns, -1, dtype=np.int64)
        self.moving = np.zeros(columns)
        self.weaved_at = np.full(columns, -math.inf)

    @property
    def table(self) -> WeaveTable:
        return WeaveTable(self.keys, self.moving, self.weaved_at)

    def column(self, vehicle: int) -> int | None:
        """The column of the vehicle of id `vehicle`, None if it was never seen."""
        found = np.flatnonzero(self.keys == vehicle)
        return int(found[0]) if found.size else None

    def room(self, ids: np.ndarray) -> None:
        """Free columns for the vehicles of `ids` (ids >= 0: -1 marks a free column), the table at
        most half full after they are taken."""
        if ids.size and int(ids.min()) < 0:
            raise ValueError(f"the weave memory keys vehicles by id >= 0: got {int(ids.min())}")
        vehicles = ids.size
        used = self.keys >= 0
        size = self.keys.size
        while 2 * (int(used.sum()) + vehicles) > size:
            size *= 2
        if size == self.keys.size:
            return
        keys, moving, weaved_at = self.keys[used], self.moving[used], self.weaved_at[used]
        self.keys = np.full(size, -1, dtype=np.int64)
        self.moving, self.weaved_at = np.zeros(size), np.full(size, -math.inf)
        for vehicle, way, at in zip(keys.tolist(), moving.tolist(), weaved_at.tolist(), strict=True):
            column = column_of(self.keys, vehicle)
            self.moving[column], self.weaved_at[column] = way, at


@register_jitable
def weavers_in_rows(
    world: LeaderRows, heading_for: float, wary_s: float, found: int, out: FoundLeaders
) -> int:
    """Appends to the `found` vehicles already in `out` (the leaders and the cars the cruise alone
    keeps, `controllers.leaders.leaders_in_rows`; none twice) each vehicle that turned back less
    than `wary_s` [s] ago (`world.weaved_s`), ahead of the ego (its centre ahead of the ego's) with
    its centre in a lane next to the one centred at `heading_for` [m] (the lane the ego keeps or
    heads for), unless the ego, faster, passes it sooner than it could fall back behind it
    (`passes_sooner_than_falls_back`); returns the new count."""
    s, d, speed, length, width = world.s, world.d, world.speed, world.length, world.lane_width
    total = found
    for row in range(1, world.vehicles):
        rel = s[row] - s[0]
        if rel <= 0 or world.weaved_s[row] >= wary_s or is_listed(out.rows, total, row):
            continue
        if abs(abs(d[row] - heading_for) - width) > width / 2:
            continue
        lengths = (length[row] + length[0]) / 2
        closing = speed[0] - speed[row]
        if closing > 0 and passes_sooner_than_falls_back(rel, closing, lengths):
            continue
        out.gaps[total], out.speeds[total], out.rows[total] = rel - lengths, speed[row], row
        total += 1
    return total
