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
ANTICIPATION_ONSET_MPS2 = 2.0
"""A steady deceleration the ego needs for a leader beyond this is braked for now, in part
[m/s^2] (`anticipated`): the time-gap law alone lets a slower car far ahead come within reach of
the comfort braking first (at 30 m/s it still accelerates towards a stopped car 200 m ahead), and
emergency braking takes over. Below it, the time-gap law's later braking suffices."""
ANTICIPATED_MPS2 = 2.5
"""The steady deceleration the anticipation settles at [m/s^2]: below the comfort deceleration
(3), so the need, held there, does not grow into emergency braking's. Onset and settling point
were chosen on development seeds 1059000-1059099 among (1.0, 1.5), (1.5, 2.0) and (2.0, 2.5):
the earlier the onset, the more an agent slows for a wreck far ahead it would rather pass."""


class GapKeeping(NamedTuple):
    """The cruise's time-gap law: keep `standstill_gap` [m] + `time_gap` [s] x speed to a leader."""

    time_gap: float
    standstill_gap: float


@register_jitable
def gap_acceleration(law: GapKeeping, speed: float, gap: float, leader_speed: float) -> float:
    """The acceleration [m/s^2] that keeps the time gap to one leader `gap` [m] ahead at
    `leader_speed` [m/s] from the ego's `speed` [m/s]: KP_GAP on the gap error, KP_CLOSING on the
    closing speed, and no less braking than `anticipated` gives for the steady need
    (`approach_deceleration`) of a slower leader far ahead."""
    desired_gap = law.standstill_gap + law.time_gap * speed
    closing = speed - leader_speed
    keeping = KP_GAP * (gap - desired_gap) - KP_CLOSING * closing
    anticipating = anticipated(approach_deceleration(law, gap, closing, leader_speed))
    return min(keeping, -anticipating) if anticipating > 0 else keeping


@register_jitable
def approach_deceleration(law: GapKeeping, gap: float, closing: float, leader_speed: float) -> float:
    """The steady deceleration [m/s^2] that brings the ego, closing in at `closing` [m/s] on a
    leader `gap` [m] ahead, to the leader's `leader_speed` [m/s] at the time gap it keeps behind
    it then; 0 when it does not close in or is already within that gap (the time-gap law's
    own braking there)."""
    room = gap - (law.standstill_gap + law.time_gap * leader_speed)
    return closing * closing / (2 * room) if closing > 0 and room > 0 else 0.0


@register_jitable
def stopping_deceleration(speed: float, gap: float, leader_speed: float, braking: float) -> float:
    """The steady deceleration [m/s^2] that stops the ego at `speed` [m/s] `STOP_MARGIN_M` behind
    where a leader `gap` [m] ahead at `leader_speed` [m/s], braking at `braking` [m/s^2], stops; 0
    when the leader is not seen braking (`BRAKING_SEEN_MPS2`) or the ego does not close in."""
    if braking <= BRAKING_SEEN_MPS2 or speed <= leader_speed:
        return 0.0
    room = max(gap - STOP_MARGIN_M, 0.01)
    return speed * speed / (2 * (room + leader_speed * leader_speed / (2 * braking)))


@register_jitable
def anticipated(needed: float) -> float:
    """The deceleration [m/s^2] braked now for a steady deceleration `needed` [m/s^2]: 0 up to
    `ANTICIPATION_ONSET_MPS2`, then rising steeply enough to equal the need at `ANTICIPATED_MPS2`,
    continuous (no switching back and forth at the onset), so a need growing past the onset is
    held about there: braking less than the need lets it grow, more lets it shrink."""
    gain = ANTICIPATED_MPS2 / (ANTICIPATED_MPS2 - ANTICIPATION_ONSET_MPS2)
    return max(needed - ANTICIPATION_ONSET_MPS2, 0.0) * gain


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
    return (
        closing * closing / (2 * room) > limits.comfort_deceleration
        or gap / closing < limits.trigger_ttc_s
        or stopping_deceleration(speed, gap, leader_speed, braking) > limits.comfort_deceleration
    )
