"""The longitudinal laws the stack's controllers run and the planners that forecast them model: the
adaptive cruise's time-gap law (`gap_acceleration`) and emergency braking's trigger
(`needs_full_braking`). Plain functions that numba compiles, shared by `controllers` (the per-world
classes, the batch's kernels) and `planner` (the lookahead's rollout, the safety layer's forecast),
so a forecast is the law the car runs."""

from __future__ import annotations

from typing import NamedTuple

from numba.extending import register_jitable

KP_GAP = 0.25
"""Gap-error gain [1/s^2]."""
KP_CLOSING = 0.8
"""Relative-speed gain [1/s]."""
STOP_MARGIN_M = 1.0
"""Gap kept when stopping behind a leader [m]."""
BRAKING_SEEN_MPS2 = 0.5
"""A leader slowing faster than this is braking: the ego must stop behind where it stops [m/s^2]."""


class GapKeeping(NamedTuple):
    """The cruise's time-gap law: keep `standstill_gap` [m] + `time_gap` [s] x speed to a leader."""

    time_gap: float
    standstill_gap: float


@register_jitable
def gap_acceleration(law: GapKeeping, speed: float, gap: float, leader_speed: float) -> float:
    """The acceleration [m/s^2] that keeps the time gap to one leader `gap` [m] ahead at
    `leader_speed` [m/s] from the ego's `speed` [m/s]: KP_GAP on the gap error, KP_CLOSING on the
    closing speed."""
    desired_gap = law.standstill_gap + law.time_gap * speed
    closing = speed - leader_speed
    return KP_GAP * (gap - desired_gap) - KP_CLOSING * closing


class BrakingLimits(NamedTuple):
    """Emergency braking's settings: full braking [m/s^2], the comfort deceleration it steps in
    beyond [m/s^2], and the time to collision that triggers it [s]."""

    max_deceleration: float
    comfort_deceleration: float
    trigger_ttc_s: float


@register_jitable
def needs_full_braking(
    limits: BrakingLimits, speed: float, gap: float, leader_speed: float, braking: float
) -> bool:
    """Whether the ego at `speed` [m/s] needs more than comfort braking for a leader `gap` [m] ahead
    at `leader_speed` [m/s], braking at `braking` [m/s^2] (`EmergencyBraking.needed`)."""
    closing = speed - leader_speed
    if closing <= 0:
        return False
    room = max(gap - STOP_MARGIN_M, 0.01)
    stopping = braking > BRAKING_SEEN_MPS2
    stops_in = leader_speed * leader_speed / (2 * braking) if stopping else 0.0
    return (
        closing * closing / (2 * room) > limits.comfort_deceleration
        or gap / closing < limits.trigger_ttc_s
        or (stopping and speed * speed / (2 * (room + stops_in)) > limits.comfort_deceleration)
    )
