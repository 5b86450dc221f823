"""The world snapshot every layer reads, the ego as the controllers see it, and a neighbour's record
(`common.neighbours` finds them, `controllers.leaders` picks the cruise's leaders)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

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
    speed [m/s]. The adaptive cruise keeps a time gap to those ahead (its leaders, `controllers.leaders`)."""

    gap: float
    speed: float
    vehicle: int = -1
    """Which vehicle (its id in the world), so a tracker can follow it from tick to tick."""
    may_turn_back: bool = False
    """A vehicle that may come into the lane the ego fills but has not yet: one between lanes close
    ahead, moving away, that could turn back (`controllers.leaders.turning_back_in_rows`), or one
    beside the ego in the lane beyond the target of its lane change (`beside_beyond_in_rows`). The
    cruise keeps its time gap to it, emergency braking does not fire for it."""


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
        s, reference = float(self.s[0]), self.lanes[0]
        return EgoState(
            d=float(self.d[0]),
            heading=float(self.heading[0]) - reference.heading_at(s),
            speed=float(self.speed[0]),
            curvature=lane_curvature(reference, s),
            lateral_speed=self.ego_lateral_speed,
            yaw_rate=self.ego_yaw_rate,
        )
