"""Adaptive cruise (longitudinal): a speed PI capped by a constant-time-gap law for every leader."""

from __future__ import annotations

from common.longitudinal import KP_CLOSING, KP_GAP, GapKeeping, gap_acceleration
from controllers.pid import PID
from records import Neighbour, clip


class AdaptiveCruise:
    """Hold a set speed; keep standstill_gap + time_gap * v to each leader (the ego lane's and,
    during a lane change, the target lane's), down to standstill at standstill_gap behind a stopped
    leader, and off again when it leaves (`gap_acceleration`). Braking is limited to the comfort
    deceleration: beyond it `controllers.emergency.EmergencyBraking` takes over."""

    KP_GAP = KP_GAP
    KP_CLOSING = KP_CLOSING

    def __init__(
        self,
        time_gap: float,
        standstill_gap: float,
        comfort_deceleration: float,
        kp_speed: float = 0.6,
        ki_speed: float = 0.05,
        max_acceleration: float = 2.0,
    ) -> None:
        self.law = GapKeeping(time_gap, standstill_gap)
        self.speed_pid = PID(kp=kp_speed, ki=ki_speed, limits=(-comfort_deceleration, max_acceleration))

    @property
    def comfort_deceleration(self) -> float:
        """The most the cruise brakes [m/s^2] (its speed PI's lower limit, negated)."""
        return -self.speed_pid.low

    @property
    def max_acceleration(self) -> float:
        """The most the cruise accelerates [m/s^2] (its speed PI's upper limit)."""
        return self.speed_pid.high

    def reset(self) -> None:
        self.speed_pid.reset()

    def update(self, speed: float, set_speed: float, leaders: tuple[Neighbour, ...], dt: float) -> float:
        """Acceleration command [m/s^2]."""
        command = self.speed_pid.update(set_speed - speed, dt)
        for leader in leaders:
            command = min(command, gap_acceleration(self.law, speed, leader.gap, leader.speed))
        return clip(command, self.speed_pid.low, self.speed_pid.high)
