"""Cascaded lateral PID on the kinematic bicycle, with feedforward from the reference.

Design. The steering is computed from a commanded yaw rate r through beta = asin(L/2 r / v), so
psi' = r exactly: the heading loop r = r_ff + kp_heading (psi_cmd - psi) is first order with time
constant 1 / kp_heading. The outer loop commands the course: chi_cmd = asin((d_dot_ref + kp e +
ki int e) / v) with e = d_ref - d, fed forward by chi_ff' = d_ddot_ref / v and by the road's
curvature (r_ff += kappa v). The plant's course is psi + beta, so the heading command subtracts the
slip of the feedforward yaw rate. Linearised (small angles) in error coordinates the loop is

    e' = -v psi_e,  psi_e' = kp_h (kp e + ki z) / v - kp_h psi_e,  z' = e,

whose characteristic polynomial s^3 + kp_h s^2 + kp_h kp s + kp_h ki does not depend on the speed:
the defaults (kp_h 6, kp 2, ki 0.05) put the poles at -2.99 +- 1.71j and -0.025 (python-control,
`closed_loop`; checked in the tests): a step in d_ref rises in 0.76 s, settles (2 %) in 1.2 s with
1.7 % overshoot, at any speed; the slow integrator pole only trims steady offsets. Tuned with
`drivestack track`: with the feedforward, the lane change itself needs little feedback.
"""

from __future__ import annotations

import math

import control
import numpy as np

from controllers.config import PIDGains
from controllers.pid import PID
from records import EgoState, Reference

LENGTH = 5.0
"""Wheelbase of highway-env's bicycle [m]."""
MIN_SPEED = 1.0
"""Below this speed [m/s] the lateral law is evaluated at MIN_SPEED, avoiding division by ~0."""


def closed_loop(gains: PIDGains, speed: float = 25.0) -> control.StateSpace:
    """The linearised lateral loop above, input d_ref, output d (for poles and step_info)."""
    kp, ki, kh, v = gains.kp_lateral, gains.ki_lateral, gains.kp_heading, speed
    # states: d, psi, z (= integral of d_ref - d)
    a = np.array([[0.0, v, 0.0], [-kh * kp / v, -kh, kh * ki / v], [-1.0, 0.0, 0.0]])
    b = np.array([[0.0], [kh * kp / v], [1.0]])
    return control.ss(a, b, np.array([[1.0, 0.0, 0.0]]), np.zeros((1, 1)))


class LateralPID:
    """Steering command [rad] from lateral and heading errors; stateful (integrator, last steering)."""

    def __init__(self, gains: PIDGains) -> None:
        self.gains = gains
        self.lateral = PID(kp=gains.kp_lateral, ki=gains.ki_lateral, limits=(-10.0, 10.0))
        self.last_steering = 0.0

    def reset(self) -> None:
        self.lateral.reset()
        self.last_steering = 0.0

    def update(self, state: EgoState, reference: Reference, dt: float) -> float:
        gains = self.gains
        v = max(state.speed, MIN_SPEED)
        lateral_speed = self.lateral.update(reference.d - state.d, dt, feedforward=reference.d_dot)
        course = math.asin(float(np.clip(lateral_speed / v, -0.5, 0.5)))
        feedforward_rate = reference.d_ddot / v + state.curvature * v
        slip = math.asin(float(np.clip(LENGTH / 2 * feedforward_rate / v, -0.5, 0.5)))
        yaw_rate = feedforward_rate + gains.kp_heading * (course - slip - state.heading)
        beta = math.asin(float(np.clip(LENGTH / 2 * yaw_rate / v, -0.7, 0.7)))
        step = gains.steering_rate * dt
        steering = float(
            np.clip(
                math.atan(2 * math.tan(beta)),
                max(-gains.max_steering, self.last_steering - step),
                min(gains.max_steering, self.last_steering + step),
            )
        )
        self.last_steering = steering
        return steering
