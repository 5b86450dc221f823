"""Record types of the control layer."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Actuation:
    """What the plant receives each tick: acceleration [m/s^2] and front-wheel steering angle [rad]."""

    acceleration: float
    steering: float


@dataclass(frozen=True)
class Leader:
    """A vehicle the longitudinal controller must not close on: bumper-to-bumper gap [m], speed [m/s]."""

    gap: float
    speed: float


@dataclass(frozen=True)
class EgoState:
    """The ego in the lane frame: lateral offset d [m], heading relative to the lane [rad], speed
    [m/s], and the lane's curvature at the ego [1/m] (positive turning left)."""

    d: float
    heading: float
    speed: float
    curvature: float = 0.0


@dataclass(frozen=True)
class Reference:
    """What to track this tick: lateral offset and its first two time derivatives (m, m/s, m/s^2),
    a set speed [m/s], and the leaders to keep a time gap to."""

    d: float
    d_dot: float
    d_ddot: float
    set_speed: float
    leaders: tuple[Leader, ...] = ()
    preview: tuple[tuple[float, float], ...] = ()
    """(d [m], d_dot [m/s]) at the next control ticks, for controllers that look ahead."""
