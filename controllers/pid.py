"""PID building block and the lane-change tracker: cascaded lateral PID + adaptive cruise.

Design (kinematic bicycle, CoG at mid-length, L = 5 m): the heading loop is exact, because the
steering is computed from the commanded yaw rate r through beta = asin(L/2 r / v), which makes
psi' = r. It is a first-order loop with time constant 1 / KP_HEADING. The lateral loop sees
d' = v sin(psi + beta) ~ v psi, another integrator, closed by a PI on lateral error with the
reference's d_dot and d_ddot fed forward; its bandwidth KP_LATERAL sits well below the heading
loop's (cascade separation >= 4x).
"""

from __future__ import annotations

import math

import numpy as np

from controllers.types import Actuation, EgoState, Leader, Reference


class PID:
    """A small stateful PID with output limits, an output rate limit and clamp anti-windup.

    The integrator only moves when the output is not saturated, or when the error pulls it back
    out of saturation (clamping, as openpilot's `PIDController`).
    """

    def __init__(
        self,
        kp: float,
        ki: float = 0.0,
        kd: float = 0.0,
        limits: tuple[float, float] = (-math.inf, math.inf),
        rate_limit: float = math.inf,
    ) -> None:
        for name, value in (("kp", kp), ("ki", ki), ("kd", kd), ("rate_limit", rate_limit)):
            if not value >= 0:
                raise ValueError(f"PID {name} must be >= 0, got {value}")
        if not limits[0] < limits[1]:
            raise ValueError(f"PID limits must be (low, high) with low < high, got {limits}")
        self.kp, self.ki, self.kd = kp, ki, kd
        self.low, self.high = limits
        self.rate_limit = rate_limit
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0
        self.output: float | None = None

    def update(self, error: float, dt: float, error_rate: float = 0.0, feedforward: float = 0.0) -> float:
        proportional_part = self.kp * error + self.kd * error_rate + feedforward
        candidate = self.integral + self.ki * error * dt
        unclamped = proportional_part + candidate
        saturated_high = unclamped > self.high and error > 0
        saturated_low = unclamped < self.low and error < 0
        if not (saturated_high or saturated_low):
            self.integral = candidate
        output = float(np.clip(proportional_part + self.integral, self.low, self.high))
        if self.output is not None:
            step = self.rate_limit * dt
            output = float(np.clip(output, self.output - step, self.output + step))
        self.output = output
        return output


class AdaptiveCruise:
    """Longitudinal control: a speed PI, capped by a constant-time-gap law for every leader.

    Desired gap = standstill_gap + time_gap * v. Braking is limited to the comfort deceleration
    unless the kinematic stopping need (closing^2 / 2 gap) exceeds it: then up to full braking.
    """

    MAX_ACCELERATION = 2.0
    """Largest commanded acceleration [m/s^2]."""
    EMERGENCY_DECELERATION = 5.0
    """Full braking, used only when a collision is imminent [m/s^2]."""
    KP_GAP = 0.25
    """Gap-error gain [1/s^2]."""
    KP_CLOSING = 0.8
    """Relative-speed gain [1/s]."""

    def __init__(self, time_gap: float, standstill_gap: float, comfort_deceleration: float) -> None:
        self.time_gap = time_gap
        self.standstill_gap = standstill_gap
        self.comfort_deceleration = comfort_deceleration
        self.speed_pid = PID(kp=0.6, ki=0.05, limits=(-comfort_deceleration, self.MAX_ACCELERATION))

    def reset(self) -> None:
        self.speed_pid.reset()

    def update(self, speed: float, set_speed: float, leaders: tuple[Leader, ...], dt: float) -> float:
        """Acceleration command [m/s^2]."""
        command = self.speed_pid.update(set_speed - speed, dt)
        floor = -self.comfort_deceleration
        for leader in leaders:
            desired_gap = self.standstill_gap + self.time_gap * speed
            closing = speed - leader.speed
            gap_law = self.KP_GAP * (leader.gap - desired_gap) - self.KP_CLOSING * closing
            command = min(command, gap_law)
            if closing > 0:
                stopping_need = closing**2 / (2.0 * max(leader.gap - 1.0, 0.1))
                if stopping_need > self.comfort_deceleration:
                    floor = -self.EMERGENCY_DECELERATION
                    command = min(command, -stopping_need)
        return float(np.clip(command, floor, self.MAX_ACCELERATION))


class PIDTracker:
    """Lane-change tracking: cascaded lateral PID for steering, adaptive cruise for throttle."""

    KP_LATERAL = 1.0
    """Lateral position gain [1/s]."""
    KI_LATERAL = 0.1
    """Lateral integral gain [1/s^2]."""
    KP_HEADING = 4.0
    """Heading gain [1/s]."""
    MAX_STEERING = math.pi / 4
    """Steering limit [rad] (highway-env's ContinuousAction range)."""
    STEERING_RATE = 1.0
    """Steering rate limit [rad/s]."""
    LENGTH = 5.0
    """Wheelbase of highway-env's bicycle [m]."""
    MIN_SPEED = 1.0
    """Below this speed [m/s] the lateral law is evaluated at MIN_SPEED, avoiding division by ~0."""

    def __init__(self, cruise: AdaptiveCruise) -> None:
        self.lateral = PID(kp=self.KP_LATERAL, ki=self.KI_LATERAL, limits=(-10.0, 10.0))
        self.cruise = cruise
        self.last_steering = 0.0

    def reset(self) -> None:
        self.lateral.reset()
        self.cruise.reset()
        self.last_steering = 0.0

    def step(self, state: EgoState, reference: Reference, dt: float) -> Actuation:
        v = max(state.speed, self.MIN_SPEED)
        lateral_speed = self.lateral.update(reference.d - state.d, dt, feedforward=reference.d_dot)
        course = math.asin(float(np.clip(lateral_speed / v, -0.5, 0.5)))
        course_rate = reference.d_ddot / v
        yaw_rate = course_rate + self.KP_HEADING * (course - state.heading)
        slip = math.asin(float(np.clip(self.LENGTH / 2 * yaw_rate / v, -0.7, 0.7)))
        step = self.STEERING_RATE * dt
        steering = float(
            np.clip(
                math.atan(2 * math.tan(slip)),
                max(-self.MAX_STEERING, self.last_steering - step),
                min(self.MAX_STEERING, self.last_steering + step),
            )
        )
        self.last_steering = steering
        acceleration = self.cruise.update(state.speed, reference.set_speed, reference.leaders, dt)
        return Actuation(acceleration=acceleration, steering=steering)
