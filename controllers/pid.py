"""A small stateful PID with output limits, a rate limit and clamp anti-windup."""

from __future__ import annotations

import math

from records import clip


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
        output = clip(proportional_part + self.integral, self.low, self.high)
        if self.output is not None:
            step = self.rate_limit * dt
            output = clip(output, self.output - step, self.output + step)
        self.output = output
        return output
