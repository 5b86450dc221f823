"""Controllers behind one verb, `step(state, reference, dt) -> Actuation`, keyed by name."""

from __future__ import annotations

from controllers.config import MPCSettings, PIDGains
from controllers.cruise import AdaptiveCruise
from controllers.lateral import LateralPID
from controllers.types import Actuation, EgoState, Reference

CONTROLLER_NAMES = ("pid", "mpc")


class PIDTracker:
    """Lateral PID for steering, adaptive cruise for throttle."""

    preview_steps = 0

    def __init__(self, gains: PIDGains, cruise: AdaptiveCruise) -> None:
        self.lateral = LateralPID(gains)
        self.cruise = cruise

    def reset(self) -> None:
        self.lateral.reset()
        self.cruise.reset()

    def step(self, state: EgoState, reference: Reference, dt: float) -> Actuation:
        steering = self.lateral.update(state, reference, dt)
        acceleration = self.cruise.update(state.speed, reference.set_speed, reference.leaders, dt)
        return Actuation(acceleration=acceleration, steering=steering)


def make_tracker(name: str, gains: PIDGains, mpc: MPCSettings, cruise: AdaptiveCruise, dt: float):
    """The controller `name` (pid or mpc); the MPC falls back to a PID tracker of its own."""
    if name == "pid":
        return PIDTracker(gains, cruise)
    if name == "mpc":
        from controllers.mpc import MPCTracker

        return MPCTracker(mpc, dt, fallback=PIDTracker(gains, cruise))
    raise ValueError(f"unknown controller {name!r}; available: {', '.join(CONTROLLER_NAMES)}")
