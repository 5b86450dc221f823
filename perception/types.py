"""Shared record types: the world snapshot every layer may read.

This is the one module `stack`, `perception`, `planner` and `controllers` all import. It holds
plain data only: no highway-env import, no behaviour beyond small derived views.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class Lane(Protocol):
    """The lane-geometry surface the layers use (highway-env's `AbstractLane` satisfies it)."""

    width: float

    def local_coordinates(self, position: np.ndarray) -> tuple[float, float]: ...

    def position(self, longitudinal: float, lateral: float) -> np.ndarray: ...

    def heading_at(self, longitudinal: float) -> float: ...


@dataclass(frozen=True)
class VehicleState:
    """One vehicle at one instant. Positions in m (world frame), heading in rad, speeds in m/s."""

    id: int
    x: float
    y: float
    heading: float
    speed: float
    vx: float
    vy: float
    lane: int
    length: float
    width: float
    s: float
    d: float
    crashed: bool


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

    @property
    def count(self) -> int:
        return len(self.ids)

    @property
    def lanes_count(self) -> int:
        return len(self.lanes)

    @property
    def lane_width(self) -> float:
        return float(self.lanes[0].width)

    def vehicle(self, row: int) -> VehicleState:
        """The vehicle in row `row` as a scalar record (row 0 is the ego)."""
        return VehicleState(
            id=int(self.ids[row]),
            x=float(self.position[row, 0]),
            y=float(self.position[row, 1]),
            heading=float(self.heading[row]),
            speed=float(self.speed[row]),
            vx=float(self.velocity[row, 0]),
            vy=float(self.velocity[row, 1]),
            lane=int(self.lane[row]),
            length=float(self.length[row]),
            width=float(self.width[row]),
            s=float(self.s[row]),
            d=float(self.d[row]),
            crashed=bool(self.crashed[row]),
        )

    @property
    def ego(self) -> VehicleState:
        return self.vehicle(0)
