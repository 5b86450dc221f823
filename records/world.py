"""The world snapshot every layer reads, and the ego and its neighbours as the controllers see them."""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from records.compiled import Kernel


class Lane(Protocol):
    """The lane-geometry surface the layers use (highway-env's `AbstractLane` satisfies it)."""

    width: float

    def local_coordinates(self, position: np.ndarray) -> tuple[float, float]: ...

    def position(self, longitudinal: float, lateral: float) -> np.ndarray: ...

    def heading_at(self, longitudinal: float) -> float: ...


def lane_curvature(lane: Lane, s: float) -> float:
    """Curvature [1/m] of `lane` at `s`: central difference of its heading over +-1 m."""
    return (lane.heading_at(s + 1.0) - lane.heading_at(s - 1.0)) / 2.0


@dataclass(frozen=True)
class Neighbour:
    """A vehicle ahead of or behind the ego: bumper-to-bumper gap [m] (negative = overlapping) and
    speed [m/s]. The adaptive cruise keeps a time gap to those ahead (its leaders)."""

    gap: float
    speed: float
    vehicle: int = -1
    """Which vehicle (its id in the world), so a tracker can follow it from tick to tick."""


LEAVING_M = 1.0
"""A leader whose centre is farther than this from the lane's centre is leaving (or entering) the
lane, and no longer hides the vehicle ahead of it [m]."""


SIDE_MARGIN_M = 0.3
"""Lateral room a passed vehicle must still have to the ego's side when the ego is by [m]."""


@dataclass(frozen=True)
class EgoState:
    """The ego in the frame of the reference lane: lateral offset d [m], heading relative to the
    lane [rad], speed [m/s], the lane's curvature at the ego [1/m] (positive turning left), and,
    in the body frame, lateral speed [m/s] and yaw rate [rad/s]."""

    d: float
    heading: float
    speed: float
    curvature: float = 0.0
    lateral_speed: float = 0.0
    yaw_rate: float = 0.0

    @property
    def d_dot(self) -> float:
        """Lateral speed in the lane frame [m/s]: the body velocity (speed, lateral_speed) turned by
        the heading, so a sideslipping car's course counts, not only where it points."""
        return self.speed * math.sin(self.heading) + self.lateral_speed * math.cos(self.heading)


@dataclass(frozen=True)
class WorldState:
    """A snapshot of the road at one control tick, as struct-of-arrays; row 0 is the ego.

    `s` and `d` are the longitudinal and lateral coordinates (m) of each vehicle in the frame of
    the reference lane (lane 0 of the ego's road segment), so lane `k`'s centre lies at
    `d = lane_offsets[k]`. `lanes` gives the geometry of every lane of that segment.
    """

    time: float
    ids: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    velocity: np.ndarray
    lane: np.ndarray
    length: np.ndarray
    width: np.ndarray
    s: np.ndarray
    d: np.ndarray
    crashed: np.ndarray
    lanes: tuple[Lane, ...]
    lane_offsets: np.ndarray
    ego_lateral_speed: float = 0.0
    """The ego's body-frame lateral speed [m/s] (the dynamic plant's slip; v sin(beta) kinematic)."""
    ego_yaw_rate: float = 0.0
    """The ego's yaw rate [rad/s]."""

    @property
    def count(self) -> int:
        return len(self.ids)

    @property
    def lanes_count(self) -> int:
        return len(self.lanes)

    @property
    def lane_width(self) -> float:
        return float(self.lanes[0].width)

    @property
    def ego_lane(self) -> int:
        return int(self.lane[0])

    def ego_state(self) -> EgoState:
        """The ego in the reference lane's frame, where `d` is measured, with that lane's curvature."""
        kept = _kept(self)
        cached = kept.get("ego_state")
        if cached is None:
            s, reference = float(self.s[0]), self.lanes[0]
            cached = kept["ego_state"] = EgoState(
                d=float(self.d[0]),
                heading=float(self.heading[0]) - reference.heading_at(s),
                speed=float(self.speed[0]),
                curvature=lane_curvature(reference, s),
                lateral_speed=self.ego_lateral_speed,
                yaw_rate=self.ego_yaw_rate,
            )
        return cached

    def lateral_extent(self) -> np.ndarray:
        """Each other vehicle's footprint width across the road [m]: its rectangle turned by its
        heading relative to the lane at the ego (a car nosing into a lane at 30 deg reaches 2.4 m
        further across than its width says); computed once per snapshot (`leaders`, every lane's
        neighbours and each merging car's check read it)."""
        kept = _kept(self)
        extent = kept.get("lateral_extent")
        if extent is None:
            heading = self.heading[1:] - self.lanes[0].heading_at(float(self.s[0]))
            extent = np.abs(self.length[1:] * np.sin(heading)) + np.abs(self.width[1:] * np.cos(heading))
            kept["lateral_extent"] = extent
        return extent

    def neighbours(self, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
        """(closest vehicle ahead, closest vehicle behind) of the ego among those whose footprint
        (`lateral_extent`) reaches into `lane`; ahead/behind by centre position along the road.

        Every lane's rows are found at once, on the first query, and kept for the snapshot (which,
        like every record, is never changed once made) while it lives."""
        kept = _kept(self)
        cache = kept.get("neighbours")
        if cache is None:
            cache = kept["neighbours"] = {}
        found = cache.get(lane)
        if found is None:
            found = cache[lane] = self._neighbours_from_table(lane)
        return found

    def _neighbours_from_table(self, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
        kept = _kept(self)
        if "table" not in kept:
            kept["table"] = self._neighbour_rows()
        table = kept["table"]
        lanes = len(self.lane_offsets)
        if table is None or not -lanes <= lane < lanes:
            return self._neighbours_of(lane)
        rows, found, gap, speed, ids = table
        ahead, behind = (
            Neighbour(gap[row], speed[row], ids[row]) if found[side][lane] else None
            for side in (0, 1)
            for row in (rows[side][lane],)
        )
        return ahead, behind

    def _neighbour_rows(
        self,
    ) -> tuple[list[list[int]], list[list[bool]], list[float], list[float], list[int]] | None:
        """For each side (ahead, behind) and lane, the row (among the others) `_neighbours_of`
        picks and whether there is one, with every other vehicle's gap, speed and id; every lane in
        one compiled pass (None where a distance is infinite, then `_neighbours_of` answers)."""
        if self.count < 2:
            return None
        rel_s = self.s[1:] - self.s[0]
        reach = (self.lane_width + self.lateral_extent()) / 2
        nearest = _nearest_in_lanes(rel_s, np.ascontiguousarray(self.d[1:]), self.lane_offsets, reach)
        if nearest is None:
            return None
        rows, found = nearest
        gap = np.abs(rel_s) - (self.length[1:] + self.length[0]) / 2
        return rows.tolist(), found.tolist(), gap.tolist(), self.speed[1:].tolist(), self.ids[1:].tolist()

    def _neighbours_of(self, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
        rel_s = self.s[1:] - self.s[0]
        gap = np.abs(rel_s) - (self.length[1:] + self.length[0]) / 2
        in_lane = np.abs(self.d[1:] - self.lane_offsets[lane]) < (self.lane_width + self.lateral_extent()) / 2
        found: list[Neighbour | None] = []
        for side in (rel_s > 0, rel_s <= 0):
            candidates = np.flatnonzero(in_lane & side)
            if candidates.size:
                row = candidates[np.argmin(np.abs(rel_s[candidates]))]
                found.append(Neighbour(float(gap[row]), float(self.speed[row + 1]), int(self.ids[row + 1])))
            else:
                found.append(None)
        return found[0], found[1]

    def passed_before_reached(self, row: int, margin: float = SIDE_MARGIN_M) -> bool:
        """Whether the ego's rear passes the front of the vehicle in `row` (slower, beside or ahead)
        before that vehicle, at its lateral speed towards the ego, comes within `margin` [m] of
        the ego's side; both keep their speeds. Never while its turned footprint
        (`lateral_extent`: a car nosing into the lane) is already that close sideways."""
        rel_s, closing = float(self.s[row] - self.s[0]), float(self.speed[0] - self.speed[row])
        clear_s = (rel_s + (self.length[0] + self.length[row]) / 2) / closing
        lane_heading = self.lanes[0].heading_at(float(self.s[row]))
        towards = math.copysign(1.0, float(self.d[0] - self.d[row]))
        lateral = towards * float(self.speed[row]) * math.sin(float(self.heading[row]) - lane_heading)
        apart = abs(float(self.d[row] - self.d[0])) - float(self.width[0]) / 2 - margin
        if apart - float(self.lateral_extent()[row - 1]) / 2 <= 0:
            return False
        side_gap = apart - float(self.width[row]) / 2
        return lateral <= 0 or clear_s < side_gap / lateral

    def leaders(self, lanes: tuple[int, ...]) -> tuple[Neighbour, ...]:
        """For each lane in `lanes`, the closest vehicle ahead reaching into it (none if nobody) and,
        while that one is leaving or entering the lane (centre more than `LEAVING_M` off the lane's
        centre), the next one ahead that it no longer hides, and so on: a cut-out reveals the car
        beyond at once. A slower vehicle entering the lane that the ego passes before it reaches
        the ego's side (`passed_before_reached`) is not followed: braking for it would only keep
        the two side by side for longer."""
        rel_s = self.s[1:] - self.s[0]
        gap = rel_s - (self.length[1:] + self.length[0]) / 2
        reach, d, ahead = (self.lane_width + self.lateral_extent()) / 2, self.d[1:], rel_s > 0
        slower = self.speed[1:] < self.speed[0]
        found: list[Neighbour] = []
        for lane in lanes:
            offset = np.abs(d - self.lane_offsets[lane])
            in_lane = (offset < reach) & ahead
            for row in (in_lane & (offset > LEAVING_M) & slower).nonzero()[0].tolist():
                in_lane[row] = not self.passed_before_reached(row + 1)
            rows = in_lane.nonzero()[0]
            for row in rows[np.argsort(rel_s[rows], kind="stable")].tolist():
                found.append(Neighbour(float(gap[row]), float(self.speed[row + 1]), int(self.ids[row + 1])))
                if offset[row] <= LEAVING_M:
                    break
        return tuple(found)


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


_KEPT: dict[int, dict[str, Any]] = {}
"""What a `WorldState` derived once (ego state, neighbours), by the snapshot's id while it lives.
Kept beside the record, not in it, so its `__dict__` stays its fields (`type(w)(**w.__dict__)`,
`dataclasses.replace`, pickling and copies see none of it)."""


def _kept(world: WorldState) -> dict[str, Any]:
    kept = _KEPT.get(id(world))
    if kept is None:
        kept = _KEPT[id(world)] = {}
        weakref.finalize(world, _KEPT.pop, id(world), None)
    return kept
