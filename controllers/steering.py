"""What the classic trackers share: the kinematic bicycle's steering for a path curvature, the
steady-state slip of a curvature, and the steering limits (angle and rate) as a stateful clamp."""

from __future__ import annotations

import math

import numpy as np

from controllers.bicycle import LENGTH
from controllers.config import SteeringLimits
from records import EgoState, Reference

MIN_SPEED = 1.0
"""Below this speed [m/s] the laws are evaluated at MIN_SPEED, avoiding division by ~0."""
MAX_SLIP = 0.7
"""Largest slip angle [rad] a curvature is turned into (|delta| = atan(2 tan 0.7) = 60 deg)."""


def slip_for_curvature(curvature: float) -> float:
    """The CoG slip angle beta [rad] that drives the kinematic bicycle on a path of `curvature`
    [1/m]: its course turns at v sin(beta) / (L/2) = v curvature."""
    return math.asin(float(np.clip(LENGTH / 2 * curvature, -MAX_SLIP, MAX_SLIP)))


def steering_for_slip(slip: float) -> float:
    """The front steering angle [rad] that gives the CoG slip angle `slip` [rad]."""
    return math.atan(2 * math.tan(float(np.clip(slip, -MAX_SLIP, MAX_SLIP))))


def path_curvature(state: EgoState, reference: Reference) -> float:
    """The reference path's curvature [1/m] at the car: the road's at its offset plus the lateral
    profile's d_ddot / v^2 (small angles)."""
    v = max(state.speed, MIN_SPEED)
    return state.curvature / (1 - state.curvature * state.d) + reference.d_ddot / v**2


class SteeringLimiter:
    """Clamps a steering command [rad] to +-max_steering and its change to steering_rate * dt."""

    def __init__(self, limits: SteeringLimits) -> None:
        self.limits = limits
        self.reset()

    def reset(self) -> None:
        self.last = 0.0

    def limit(self, steering: float, dt: float) -> float:
        step = self.limits.steering_rate * dt
        low = max(-self.limits.max_steering, self.last - step)
        high = min(self.limits.max_steering, self.last + step)
        self.last = float(np.clip(steering, low, high))
        return self.last
