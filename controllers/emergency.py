"""Emergency braking: the plant's full braking authority when comfort braking can no longer avoid a
collision, applied after whichever controller runs (PID, MPC, a plug-in), and a brake that holds
the car at standstill instead of reversing it."""

from __future__ import annotations

from records import Actuation, Neighbour


class EmergencyBraking:
    """Full braking while a leader is closing in and stopping behind it needs more than the comfort
    deceleration (constant-speed prediction: closing^2 / 2 (gap - margin)) or its time to collision
    is below `trigger_ttc_s`; released once no leader closes in. Counts activations (rising edges).

    The plant's braking authority is highway-env's ContinuousAction range, +-5 m/s^2 by default:
    the plant is left as highway-env defines it, so `max_deceleration` cannot exceed it."""

    STOP_MARGIN_M = 1.0
    """Gap kept when stopping behind a leader [m]."""

    def __init__(self, max_deceleration: float, comfort_deceleration: float, trigger_ttc_s: float) -> None:
        self.max_deceleration = max_deceleration
        self.comfort_deceleration = comfort_deceleration
        self.trigger_ttc_s = trigger_ttc_s
        self.reset()

    def reset(self) -> None:
        self.active = False
        self.activations = 0

    def needed(self, speed: float, leaders: tuple[Neighbour, ...]) -> bool:
        """Whether some leader needs more than comfort braking, or is within the trigger TTC [s]."""
        for leader in leaders:
            closing = speed - leader.speed
            if closing <= 0:
                continue
            room = max(leader.gap - self.STOP_MARGIN_M, 0.01)
            if (
                closing**2 / (2 * room) > self.comfort_deceleration
                or leader.gap / closing < self.trigger_ttc_s
            ):
                return True
        return False

    def closing_in(self, speed: float, leaders: tuple[Neighbour, ...]) -> bool:
        return any(speed > leader.speed for leader in leaders)

    def apply(
        self, actuation: Actuation, speed: float, leaders: tuple[Neighbour, ...], dt: float
    ) -> Actuation:
        """`actuation` with full braking while an emergency lasts, and never a deceleration that would
        reverse the car (speed [m/s] after one tick of `dt` [s] stays >= 0)."""
        if self.active:
            self.active = self.closing_in(speed, leaders)
        elif self.needed(speed, leaders):
            self.active = True
            self.activations += 1
        acceleration = -self.max_deceleration if self.active else actuation.acceleration
        acceleration = max(acceleration, -max(speed, 0.0) / dt)
        if acceleration == actuation.acceleration:
            return actuation
        return Actuation(acceleration=acceleration, steering=actuation.steering)
