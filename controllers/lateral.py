"""Cascaded lateral PID on the bicycle, with feedforward from the reference and the road.

Design. The steering is computed from a commanded yaw rate r through beta = asin(L/2 r / v), so
psi' = r exactly on the kinematic bicycle: the heading loop r = r_ff + kp_heading (psi_cmd - psi)
is first order with time constant 1 / kp_heading. The outer loop commands the course: chi_cmd =
asin((d_dot_ref + kp e + ki int e) / v) with e = d_ref - d, fed forward by chi_ff' = d_ddot_ref / v
and by the road's curvature at the car's offset (r_ff += v kappa / (1 - kappa d)). The plant's
course is psi + beta, so the heading command subtracts the sideslip of the feedforward yaw rate.
Linearised (small angles) in error coordinates the loop is

    e' = -v psi_e,  psi_e' = kp_h (kp e + ki z) / v - kp_h psi_e,  z' = e,

whose characteristic polynomial s^3 + kp_h s^2 + kp_h kp s + kp_h ki does not depend on the speed:
the defaults (kp_h 6, kp 2, ki 0.6) put the poles at -2.82 +- 1.42j and -0.36 (python-control,
`closed_loop`, checked in the tests). A step in d_ref without feedforward rises in 0.64 s with 13 %
overshoot and a slow tail: the integrator pole at -0.36 1/s, placed to remove a bend's residual
bias within the lane change; a lane change is fed forward and settles within 5 s (`track`).

Below FULL_BANDWIDTH_SPEED the loop is slowed in proportion to the speed: every pole is scaled by
sigma = v / FULL_BANDWIDTH_SPEED (kp_heading and kp by sigma, ki by sigma^2). The steering a yaw
rate needs grows as 1/v (delta ~ L r / v), so at full bandwidth a heading oscillation at crawl
speed asks for more steering rate than the 0.5 rad/s limit, and the rate-limited loop turns into a
growing limit cycle (seen at 5-9 m/s in stop-and-go traffic); with the poles scaled the steering
rate the loop needs falls with the speed instead.

The dynamic bicycle (tyre slip, `model="dynamic"`) differs in two ways, both speed-scheduled
model inversions rather than higher gains: (1) its steady sideslip is smaller by SLIP_GRADIENT v r
(-0.72 deg instead of +0.14 deg at 30 m/s on a 1000 m bend), which the heading command subtracts
too; (2) its yaw rate lags the steering by a first-order pole at -YAW_POLE_SPEED / v (0.23 s at
35 m/s, slower than the heading loop above ~26 m/s), which a lead on the commanded yaw rate, time
constant v / YAW_POLE_SPEED, cancels: r_cmd + tau r_cmd'. `dynamic_loop` is the linearised
loop on that plant (poles and margins at 10, 22, 35 m/s in the tests and docs/architecture.md).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numba.extending import register_jitable

from common.compiled import clip
from controllers.bicycle import CORNERING_STIFFNESS, LENGTH, MASS, SLIP_GRADIENT, YAW_POLE_SPEED
from controllers.config import PIDGains
from controllers.pid import PID_START, PIDMemory, PIDTerms, pid_output
from records import EgoState, PlantName, Reference

if TYPE_CHECKING:  # python-control (and scipy under it) loads only for the loop analyses below
    import control

MIN_SPEED = 1.0
"""Below this speed [m/s] the lateral law is evaluated at MIN_SPEED, avoiding division by ~0."""
FULL_BANDWIDTH_SPEED = 10.0
"""From this speed [m/s] up the lateral loop runs at its design gains; below, slower (see above)."""
MAX_COURSE = math.pi / 6
"""The course command's limit relative to the lane [rad]: the outer loop's lateral-speed output is
limited to +-v sin(MAX_COURSE), and its integrator clamps there (no windup at crawl speed, where a
lane change's reference asks for at most `Maneuver.max_course`, 12 deg by default)."""


class LateralGains(NamedTuple):
    """The lateral PID's gains and steering limits (`controllers.config.PIDGains`' lateral part)."""

    kp_lateral: float
    ki_lateral: float
    kp_heading: float
    steering_rate: float
    """Steering rate limit [rad/s]."""
    max_steering: float
    """Steering limit [rad]."""


@register_jitable
def bandwidth_scale(speed: float) -> float:
    """sigma in (0, 1]: how much the lateral loop's poles are slowed at `speed` [m/s]."""
    return min(1.0, max(speed, MIN_SPEED) / FULL_BANDWIDTH_SPEED)


@register_jitable
def scheduled_gains(gains: PIDGains | LateralGains, speed: float) -> tuple[float, float, float]:
    """(kp_lateral, ki_lateral, kp_heading) at `speed` [m/s]: every pole scaled by `bandwidth_scale`."""
    sigma = bandwidth_scale(speed)
    if sigma == 1.0:
        return gains.kp_lateral, gains.ki_lateral, gains.kp_heading
    return gains.kp_lateral * sigma, gains.ki_lateral * (sigma * sigma), gains.kp_heading * sigma


def closed_loop(gains: PIDGains, speed: float = 25.0) -> control.StateSpace:
    """The linearised lateral loop above, input d_ref, output d (for poles and step_info)."""
    import control

    (kp, ki, kh), v = scheduled_gains(gains, speed), speed
    # states: d, psi, z (= integral of d_ref - d)
    a = np.array([[0.0, v, 0.0], [-kh * kp / v, -kh, kh * ki / v], [-1.0, 0.0, 0.0]])
    b = np.array([[0.0], [kh * kp / v], [1.0]])
    return control.ss(a, b, np.array([[1.0, 0.0, 0.0]]), np.zeros((1, 1)))


def dynamic_loop(gains: PIDGains, speed: float) -> control.TransferFunction:
    """The loop transfer function e -> d of the PID on the linearised dynamic bicycle (broken at
    the lateral error), for poles of 1 + L and margins. With the lead the yaw rate follows its
    command exactly; the lateral speed keeps its own pole at -2 C / (m v):
    v_y' = -2C/(m v) v_y - v r + C/m delta, delta = L/v (1 + tau s) r_cmd, d' = v psi + v_y."""
    import control

    s, v = control.tf("s"), speed
    kp, ki, kh = gains.kp_lateral, gains.ki_lateral, gains.kp_heading
    lead = (LENGTH / v) * (1 + v / YAW_POLE_SPEED * s)
    lateral_speed = (CORNERING_STIFFNESS / MASS * lead - v) / (s + 2 * CORNERING_STIFFNESS / (MASS * v))
    offset = (v / s + lateral_speed) / s
    heading_loop = kh * s / (s + kh)
    return control.minreal((kp + ki / s) / v * heading_loop * offset, verbose=False)


class LateralMemory(NamedTuple):
    """What the lateral PID carries between ticks: the outer loop's PID, the last steering [rad]
    and (dynamic plant) the last commanded yaw rate [rad/s], if any."""

    lateral: PIDMemory
    steering: float
    yaw_rate: float
    has_yaw_rate: bool


LATERAL_START = LateralMemory(PID_START, 0.0, 0.0, False)
"""The lateral PID's memory after `reset`."""


@register_jitable
def lateral_steering(
    gains: LateralGains,
    memory: LateralMemory,
    d: float,
    heading: float,
    speed: float,
    curvature: float,
    d_ref: float,
    d_dot_ref: float,
    d_ddot_ref: float,
    dt: float,
    dynamic: bool,
) -> tuple[float, LateralMemory]:
    """The steering [rad] and the next memory for the ego at lateral offset `d` [m], `heading` to
    the lane [rad], `speed` [m/s] on a lane of `curvature` [1/m], following the reference (d_ref
    [m], d_dot_ref [m/s], d_ddot_ref [m/s^2]) on the kinematic bicycle, or the `dynamic` one (the
    module docstring's law)."""
    v = max(speed, MIN_SPEED)
    kp, ki, kp_heading = scheduled_gains(gains, v)
    high = v * math.sin(MAX_COURSE)
    terms = PIDTerms(kp, ki, 0.0, -high, high, math.inf)
    lateral_speed, lateral = pid_output(terms, memory.lateral, d_ref - d, 0.0, dt, d_dot_ref)
    course = math.asin(clip(lateral_speed / v, -1.0, 1.0))
    road_rate = curvature * v / (1 - curvature * d)
    feedforward_rate = d_ddot_ref / v + road_rate
    slip = math.asin(clip(LENGTH / 2 * feedforward_rate / v, -0.5, 0.5))
    if dynamic:
        slip -= SLIP_GRADIENT * v * feedforward_rate
    heading_error = course - slip - heading
    stoppable = math.sqrt(v * gains.steering_rate / LENGTH * abs(heading_error))
    yaw_rate = feedforward_rate + math.copysign(
        min(kp_heading * abs(heading_error), stoppable), heading_error
    )
    last_yaw_rate, has_yaw_rate = memory.yaw_rate, memory.has_yaw_rate
    if dynamic:
        previous = last_yaw_rate if has_yaw_rate else yaw_rate
        last_yaw_rate, has_yaw_rate = yaw_rate, True
        yaw_rate += v / YAW_POLE_SPEED * (yaw_rate - previous) / dt
    beta = math.asin(clip(LENGTH / 2 * yaw_rate / v, -0.7, 0.7))
    step = gains.steering_rate * dt
    steering = clip(
        math.atan(2 * math.tan(beta)),
        max(-gains.max_steering, memory.steering - step),
        min(gains.max_steering, memory.steering + step),
    )
    return steering, LateralMemory(lateral, steering, last_yaw_rate, has_yaw_rate)


class LateralPID:
    """Steering command [rad] from lateral and heading errors for the bicycle `model` (kinematic
    or dynamic); stateful (`LateralMemory`), the law is `lateral_steering`."""

    def __init__(self, gains: PIDGains, model: PlantName = "kinematic") -> None:
        self.gains, self.model = gains, model
        self.limits = LateralGains(
            gains.kp_lateral, gains.ki_lateral, gains.kp_heading, gains.steering_rate, gains.max_steering
        )
        self.reset()

    def reset(self) -> None:
        self.memory = LATERAL_START

    @property
    def lateral(self) -> PIDMemory:
        """The outer loop's PID memory (integral [m], last lateral-speed output [m/s])."""
        return self.memory.lateral

    @property
    def last_steering(self) -> float:
        return self.memory.steering

    def update(self, state: EgoState, reference: Reference, dt: float) -> float:
        steering, self.memory = lateral_steering(
            self.limits, self.memory, state.d, state.heading, state.speed, state.curvature,
            reference.d, reference.d_dot, reference.d_ddot, dt, self.model == "dynamic",
        )  # fmt: skip
        return steering
