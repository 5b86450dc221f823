"""A small stateful PID with output limits, a rate limit and clamp anti-windup.

The law is `pid_output`, one plain function over named records (`PIDTerms`, `PIDMemory`): the
per-world `PID` calls it on its own fields, and the batched worlds' compiled kernels call the same
function (numba compiles it where a kernel references it)."""

from __future__ import annotations

import math
from typing import NamedTuple

from numba.extending import register_jitable

from common.compiled import clip


class PIDTerms(NamedTuple):
    """A PID's gains, output limits and output rate limit [output units per second]."""

    kp: float
    ki: float
    kd: float
    low: float
    high: float
    rate_limit: float


class PIDMemory(NamedTuple):
    """What a PID carries from one tick to the next: the integral, the last output and whether there
    was one (no rate limit applies to the first)."""

    integral: float
    output: float
    has_output: bool


PID_START = PIDMemory(0.0, 0.0, False)
"""A PID's memory after `reset`."""


@register_jitable
def pid_output(
    terms: PIDTerms, memory: PIDMemory, error: float, error_rate: float, dt: float, feedforward: float
) -> tuple[float, PIDMemory]:
    """The output and the next memory: P + I + D + `feedforward` within the limits and the rate
    limit; the integrator moves only while the output is not saturated, or when the error pulls it
    back out of saturation (clamping, as openpilot's `PIDController`)."""
    proportional_part = terms.kp * error + terms.kd * error_rate + feedforward
    candidate = memory.integral + terms.ki * error * dt
    unclamped = proportional_part + candidate
    saturated_high = unclamped > terms.high and error > 0
    saturated_low = unclamped < terms.low and error < 0
    integral = memory.integral if saturated_high or saturated_low else candidate
    output = clip(proportional_part + integral, terms.low, terms.high)
    if memory.has_output:
        step = terms.rate_limit * dt
        output = clip(output, memory.output - step, memory.output + step)
    return output, PIDMemory(integral, output, True)


class PID:
    """A small stateful PID with output limits, an output rate limit and clamp anti-windup
    (`pid_output`)."""

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
        self.memory = PID_START

    @property
    def integral(self) -> float:
        return self.memory.integral

    @property
    def output(self) -> float | None:
        """The last output, None before the first."""
        return self.memory.output if self.memory.has_output else None

    @property
    def terms(self) -> PIDTerms:
        return PIDTerms(self.kp, self.ki, self.kd, self.low, self.high, self.rate_limit)

    def update(self, error: float, dt: float, error_rate: float = 0.0, feedforward: float = 0.0) -> float:
        output, self.memory = pid_output(self.terms, self.memory, error, error_rate, dt, feedforward)
        return output
