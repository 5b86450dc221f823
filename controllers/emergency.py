"""Emergency braking: the plant's full braking authority when comfort braking can no longer avoid a
collision, applied after whichever controller runs (PID, MPC, a plug-in), and a brake that holds
the car at standstill instead of reversing it."""

from __future__ import annotations

from numba.extending import register_jitable

from common.longitudinal import (
    BRAKING_SEEN_MPS2,
    STOP_MARGIN_M,
    BrakingLimits,
    anticipated,
    needs_full_braking,
    stopping_deceleration,
)
from records import Actuation, Neighbour


@register_jitable
def leader_braking(
    previous_speed: float, speed: float, previous_slowing: float, dt: float
) -> tuple[float, float]:
    """(slowing, braking) of a leader seen at `previous_speed` last tick and at `speed` [m/s] now:
    its slowing this tick [m/s^2], and the braking it shows, the lesser of this tick's slowing and
    `previous_slowing` (0 when it was not seen slowing: a one-tick dip is not braking)."""
    slowing = (previous_speed - speed) / dt
    return slowing, min(slowing, previous_slowing)


@register_jitable
def holds_braking(speed: float, gap: float, leader_speed: float) -> bool:
    """Whether an emergency braking goes on for a leader `gap` [m] ahead at `leader_speed` [m/s]
    with the ego at `speed` [m/s]: while the ego closes in on it, or is within the stop margin of it
    (a car cutting in across the ego's front, a little faster than the ego, still reaches it
    sideways: released at once, the ego would fall back at only the cruise's braking)."""
    return speed > leader_speed or (gap < STOP_MARGIN_M and speed > 0)


@register_jitable
def braked_before(
    limits: BrakingLimits, acceleration: float, speed: float, gap: float, leader_speed: float, braking: float
) -> float:
    """`acceleration` [m/s^2], and no more than minus the braking `anticipated` gives for the steady
    deceleration that stops the ego at `speed` [m/s] behind where a leader `gap` [m] ahead at
    `leader_speed` [m/s], braking at `braking` [m/s^2], stops (up to the comfort deceleration):
    the partial braking that keeps a braking leader from becoming an emergency."""
    braked = anticipated(stopping_deceleration(speed, gap, leader_speed, braking))
    return min(acceleration, -min(braked, limits.comfort_deceleration)) if braked > 0 else acceleration


@register_jitable
def braked_acceleration(
    limits: BrakingLimits, active: bool, acceleration: float, speed: float, dt: float
) -> float:
    """`acceleration` [m/s^2], full braking while an emergency is `active`, and never a deceleration
    that would reverse the car within one tick of `dt` [s]."""
    commanded = -limits.max_deceleration if active else acceleration
    return max(commanded, -max(speed, 0.0) / dt)


class EmergencyBraking:
    """Full braking while a leader is closing in and stopping behind it needs more than the comfort
    deceleration (constant-speed prediction: closing^2 / 2 (gap - margin)) or its time to collision
    is below `trigger_ttc_s`; released once no leader closes in or is within the stop margin
    (`holds_braking`). Counts activations (rising edges). Before that, a leader seen braking is
    braked for once stopping behind where it stops needs more than `ANTICIPATION_ONSET_MPS2`
    (`braked_before`: partial braking, not counted).

    The plant's braking authority is highway-env's ContinuousAction range, +-5 m/s^2 by default:
    the plant is left as highway-env defines it, so `max_deceleration` cannot exceed it."""

    STOP_MARGIN_M = STOP_MARGIN_M
    BRAKING_SEEN_MPS2 = BRAKING_SEEN_MPS2

    def __init__(self, max_deceleration: float, comfort_deceleration: float, trigger_ttc_s: float) -> None:
        self.limits = BrakingLimits(max_deceleration, comfort_deceleration, trigger_ttc_s)
        self.reset()

    def reset(self) -> None:
        self.active = False
        self.cause: int | None = None
        """The leader (its id) whose approach started the braking running now (None: none runs)."""
        self.activations = 0
        self.speeds: dict[int, float] = {}
        self.slowing: dict[int, float] = {}

    def needed(
        self, speed: float, leaders: tuple[Neighbour, ...], braking: dict[int, float] | None = None
    ) -> bool:
        """Whether some leader needs more than comfort braking, or is within the trigger TTC [s].
        A leader braking at `braking[vehicle]` [m/s^2] (above BRAKING_SEEN_MPS2 on two ticks running,
        so a one-tick dip is not braking) also needs it when the ego cannot stop at comfort
        deceleration within the gap plus the leader's own stopping distance (the constant-speed
        prediction alone sees a hard-braking leader too late)."""
        for leader in leaders:
            if needs_full_braking(
                self.limits, speed, leader.gap, leader.speed, (braking or {}).get(leader.vehicle, 0.0)
            ):
                self.cause = leader.vehicle
                return True
        return False

    def holds(self, speed: float, leaders: tuple[Neighbour, ...]) -> bool:
        """Whether a running emergency braking goes on (`holds_braking` for some leader)."""
        return any(holds_braking(speed, leader.gap, leader.speed) for leader in leaders)

    def apply(
        self, actuation: Actuation, speed: float, leaders: tuple[Neighbour, ...], dt: float
    ) -> Actuation:
        """`actuation` with full braking while an emergency lasts, and never a deceleration that would
        reverse the car (speed [m/s] after one tick of `dt` [s] stays >= 0). A leader that
        `may_turn_back` is the cruise's alone until it turns in."""
        leaders = tuple(leader for leader in leaders if not leader.may_turn_back)
        seen = {
            leader.vehicle: leader_braking(
                self.speeds[leader.vehicle], leader.speed, self.slowing.get(leader.vehicle, 0.0), dt
            )
            for leader in leaders
            if leader.vehicle in self.speeds
        }
        braking = {vehicle: rates[1] for vehicle, rates in seen.items()}
        self.speeds = {leader.vehicle: leader.speed for leader in leaders}
        self.slowing = {vehicle: rates[0] for vehicle, rates in seen.items()}
        if self.active:
            self.active = self.holds(speed, leaders)
            self.cause = self.cause if self.active else None
        elif self.needed(speed, leaders, braking):
            self.active = True
            self.activations += 1
        acceleration = actuation.acceleration
        for leader in leaders:
            acceleration = braked_before(
                self.limits, acceleration, speed, leader.gap, leader.speed, braking.get(leader.vehicle, 0.0)
            )
        acceleration = braked_acceleration(self.limits, self.active, acceleration, speed, dt)
        if acceleration == actuation.acceleration:
            return actuation
        return Actuation(acceleration=acceleration, steering=actuation.steering)
