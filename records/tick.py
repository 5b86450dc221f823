"""What flows through a decision and one control tick: the command, the reference, the actuation."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol

import numpy as np

from records.world import Neighbour


class Command(IntEnum):
    """The decision layer's output, in highway-env's LANE_LEFT / IDLE / LANE_RIGHT order."""

    LEFT = 0
    STAY = 1
    RIGHT = 2

    @property
    def lane_shift(self) -> int:
        """Change of lane index: LEFT moves towards lane 0."""
        return self.value - 1


N_ACTIONS = len(Command)
"""Size of every agent's discrete action space."""


class LateralProfile(Protocol):
    """A lateral reference over time (`controllers.reference.QuinticProfile`)."""

    def sample(self, t: float) -> tuple[float, float, float]:
        """(d [m], d_dot [m/s], d_ddot [m/s^2]) at absolute time `t` [s]."""
        ...

    def samples(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(d [m], d_dot [m/s]) at each of the absolute `times` [s]."""
        ...


@dataclass(frozen=True)
class Reference:
    """What to track this tick: lateral offset and its first two time derivatives (m, m/s, m/s^2)
    at `time` [s], a set speed [m/s], the leaders to keep a time gap to, and the lane the maneuver
    heads for. `lateral`, when given, is the whole profile, for controllers that look ahead."""

    d: float
    d_dot: float
    d_ddot: float
    set_speed: float
    leaders: tuple[Neighbour, ...] = ()
    time: float = 0.0
    target_lane: int = 0
    lateral: LateralProfile | None = None

    @classmethod
    def sampled(
        cls,
        lateral: LateralProfile,
        time: float,
        set_speed: float,
        leaders: tuple[Neighbour, ...] = (),
        target_lane: int = 0,
    ) -> Reference:
        d, d_dot, d_ddot = lateral.sample(time)
        return cls(d, d_dot, d_ddot, set_speed, leaders, time, target_lane, lateral)

    def preview(self, steps: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(d [m], d_dot [m/s]) at the next `steps` ticks of `dt` seconds; holds (d, 0) without a
        profile."""
        if self.lateral is None:
            return np.full(steps, self.d), np.zeros(steps)
        return self.lateral.samples(self.time + np.arange(1, steps + 1) * dt)


@dataclass(frozen=True)
class Actuation:
    """What the plant receives each tick: acceleration [m/s^2] and front-wheel steering angle [rad]."""

    acceleration: float
    steering: float


def clip(x: float, low: float, high: float) -> float:
    """`float(np.clip(x, low, high))` for one number, without numpy's dispatch (a few microseconds a
    call, several calls a tick): numpy's own rule, a NaN `x` stays NaN, a tie keeps the bound."""
    x = x if x != x or x > low else low
    return float(x if x != x or x < high else high)
