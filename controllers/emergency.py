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
    BRAKING_SEEN_MPS2 = 0.5
    """A leader slowing faster than this is braking: the ego must stop behind where it stops [m/s^2]."""

    def __init__(self, max_deceleration: float, comfort_deceleration: float, trigger_ttc_s: float) -> None:
        self.max_deceleration = max_deceleration
        self.comfort_deceleration = comfort_deceleration
        self.trigger_ttc_s = trigger_ttc_s
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
            closing = speed - leader.speed
            if closing <= 0:
                continue
            room = max(leader.gap - self.STOP_MARGIN_M, 0.01)
            slowing = (braking or {}).get(leader.vehicle, 0.0)
            stops_in = (
                leader.speed * leader.speed / (2 * slowing) if slowing > self.BRAKING_SEEN_MPS2 else None
            )
            if (
                closing * closing / (2 * room) > self.comfort_deceleration
                or leader.gap / closing < self.trigger_ttc_s
                or (
                    stops_in is not None
                    and speed * speed / (2 * (room + stops_in)) > self.comfort_deceleration
                )
            ):
                self.cause = leader.vehicle
                return True
        return False

    def closing_in(self, speed: float, leaders: tuple[Neighbour, ...]) -> bool:
        return any(speed > leader.speed for leader in leaders)

    def apply(
        self, actuation: Actuation, speed: float, leaders: tuple[Neighbour, ...], dt: float
    ) -> Actuation:
        """`actuation` with full braking while an emergency lasts, and never a deceleration that would
        reverse the car (speed [m/s] after one tick of `dt` [s] stays >= 0)."""
        slowing = {
            leader.vehicle: (self.speeds[leader.vehicle] - leader.speed) / dt
            for leader in leaders
            if leader.vehicle in self.speeds
        }
        braking = {vehicle: min(rate, self.slowing.get(vehicle, 0.0)) for vehicle, rate in slowing.items()}
        self.speeds, self.slowing = {leader.vehicle: leader.speed for leader in leaders}, slowing
        if self.active:
            self.active = self.closing_in(speed, leaders)
            self.cause = self.cause if self.active else None
        elif self.needed(speed, leaders, braking):
            self.active = True
            self.activations += 1
        acceleration = -self.max_deceleration if self.active else actuation.acceleration
        acceleration = max(acceleration, -max(speed, 0.0) / dt)
        if acceleration == actuation.acceleration:
            return actuation
        return Actuation(acceleration=acceleration, steering=actuation.steering)
