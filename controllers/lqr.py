"""LQR on the lateral error dynamics of highway-env's kinematic bicycle, speed-scheduled.

Design. The reference fixes a course chi_ref = asin(d_dot_ref / v) and a path curvature (road plus
d_ddot_ref / v^2) whose steady slip beta_ff (`controllers.steering`) is fed forward; the body then
points at psi_ref = chi_ref - beta_ff. With the errors x = (e_d = d - d_ref [m], e_psi = psi -
psi_ref [rad]) and the input u = beta - beta_ff [rad], linearised about the reference,

    e_d' = v e_psi + v u,    e_psi' = (2 v / L) u,

discretised as the plant integrates (forward Euler, one step per control tick dt): A = I + dt [[0, v],
[0, 0]], B = dt [v, 2 v / L]. python-control's `dlqr` gives u = -K(v) x for the weights of Bryson's
rule, Q = diag(1 / e_max^2, 1 / psi_max^2), R = 1 / beta_max^2. The gains change with the speed,
so they are computed once per settings on a grid of speeds (every `speed_step` m/s up to 40 m/s,
cached) and interpolated linearly; the steering is the one of beta_ff + u, rate- and angle-limited.

Tuning. e_max 5 cm, psi_max 0.02 rad, beta_max 0.01 rad: a lane change's feedforward carries the
motion and the feedback only removes centimetres, with steering corrections a fraction of the
0.5 rad/s rate limit. Nothing models the dynamic plant's tyre slip: on it a bend leaves a small
steady error (no integral state).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from controllers.bicycle import LENGTH
from controllers.config import LQRSettings
from controllers.steering import (
    MIN_SPEED,
    SteeringLimiter,
    path_curvature,
    slip_for_curvature,
    steering_for_slip,
)
from records import EgoState, Reference

TOP_SPEED = 40.0
"""The fastest speed the schedule covers [m/s] (the operating envelope's)."""


def error_model(speed: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the lateral error dynamics at `speed` [m/s], one forward-Euler step of `dt` [s]."""
    a = np.array([[1.0, speed * dt], [0.0, 1.0]])
    b = np.array([[speed * dt], [2 * speed * dt / LENGTH]])
    return a, b


def weights(settings: LQRSettings) -> tuple[np.ndarray, np.ndarray]:
    """(Q, R) by Bryson's rule."""
    q = np.diag([1 / settings.max_lateral_error**2, 1 / settings.max_heading_error**2])
    return q, np.array([[1 / settings.max_slip**2]])


@lru_cache(maxsize=16)
def gain_schedule(settings: LQRSettings, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(speeds [m/s], gains K [1/m, 1] per speed) from python-control's `dlqr`."""
    import control

    speeds = np.arange(MIN_SPEED, TOP_SPEED + settings.speed_step, settings.speed_step)
    q, r = weights(settings)
    gains = np.array([np.asarray(control.dlqr(*error_model(v, dt), q, r)[0]).reshape(-1) for v in speeds])
    return speeds, gains


class LateralLQR:
    """Steering [rad] from u = -K(v) (e_d, e_psi) around the reference's feedforward slip."""

    def __init__(self, settings: LQRSettings, dt: float) -> None:
        self.settings = settings
        self.speeds, self.gains = gain_schedule(settings, dt)
        self.limiter = SteeringLimiter(settings)

    def reset(self) -> None:
        self.limiter.reset()

    def gain(self, speed: float) -> np.ndarray:
        """K at `speed` [m/s], interpolated on the schedule (held beyond its ends)."""
        return np.array([np.interp(speed, self.speeds, column) for column in self.gains.T])

    def update(self, state: EgoState, reference: Reference, dt: float) -> float:
        v = max(state.speed, MIN_SPEED)
        slip = slip_for_curvature(path_curvature(state, reference))
        course = math.asin(float(np.clip(reference.d_dot / v, -0.5, 0.5)))
        error = np.array([state.d - reference.d, state.heading - (course - slip)])
        correction = -float(self.gain(v) @ error)
        return self.limiter.limit(steering_for_slip(slip + correction), dt)
