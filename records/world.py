"""The world snapshot every layer reads, and the ego and its neighbours as the controllers see them."""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


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
        further across than its width says)."""
        heading = self.heading[1:] - self.lanes[0].heading_at(float(self.s[0]))
        return np.abs(self.length[1:] * np.sin(heading)) + np.abs(self.width[1:] * np.cos(heading))

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
        rows, found, gap, speed = table
        ahead, behind = (
            Neighbour(gap[rows[side][lane]], speed[rows[side][lane]]) if found[side][lane] else None
            for side in (0, 1)
        )
        return ahead, behind

    def _neighbour_rows(self) -> tuple[list[list[int]], list[list[bool]], list[float], list[float]] | None:
        """For each side (ahead, behind) and lane, the row (among the others) `_neighbours_of`
        picks and whether there is one, with every other vehicle's gap and speed; as array
        operations over all lanes at once (None where an infinite distance could tie with the
        fill value, then `_neighbours_of` answers)."""
        if self.count < 2:
            return None
        rel_s = self.s[1:] - self.s[0]
        distance = np.abs(rel_s)
        if np.isinf(distance).any():
            return None
        in_lane = (
            np.abs(self.d[1:] - self.lane_offsets[:, None]) < (self.lane_width + self.lateral_extent()) / 2
        )
        candidates = in_lane[None, :, :] & np.stack([rel_s > 0, rel_s <= 0])[:, None, :]
        rows = np.where(candidates, distance, np.inf).argmin(axis=2)
        gap = distance - (self.length[1:] + self.length[0]) / 2
        return rows.tolist(), candidates.any(axis=2).tolist(), gap.tolist(), self.speed[1:].tolist()

    def _neighbours_of(self, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
        rel_s = self.s[1:] - self.s[0]
        gap = np.abs(rel_s) - (self.length[1:] + self.length[0]) / 2
        in_lane = np.abs(self.d[1:] - self.lane_offsets[lane]) < (self.lane_width + self.lateral_extent()) / 2
        found: list[Neighbour | None] = []
        for side in (rel_s > 0, rel_s <= 0):
            candidates = np.flatnonzero(in_lane & side)
            if candidates.size:
                row = candidates[np.argmin(np.abs(rel_s[candidates]))]
                found.append(Neighbour(float(gap[row]), float(self.speed[row + 1])))
            else:
                found.append(None)
        return found[0], found[1]

    def leaders(self, lanes: tuple[int, ...]) -> tuple[Neighbour, ...]:
        """For each lane in `lanes`, the closest vehicle ahead reaching into it (none if nobody)."""
        ahead = (self.neighbours(lane)[0] for lane in lanes)
        return tuple(leader for leader in ahead if leader is not None)


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
