"""Controllers behind one verb, `step(state, reference) -> Actuation`, built by name."""

from __future__ import annotations

import time
from typing import Protocol

from controllers.config import ControllerConfig, PIDGains
from controllers.cruise import AdaptiveCruise
from controllers.lateral import LateralPID
from records import Actuation, EgoState, PlantName, Reference


class Controller(Protocol):
    """Steering and throttle for one control tick of a fixed period. `solve_times` [s] holds the
    computing time of every step; `fallbacks` counts steps that fell back to a simpler law."""

    fallbacks: int
    solve_times: list[float]

    def reset(self) -> None: ...

    def step(self, state: EgoState, reference: Reference) -> Actuation: ...


class PIDTracker:
    """Lateral PID for steering, adaptive cruise for throttle, at a control period of `dt` [s]."""

    def __init__(self, gains: PIDGains, cruise: AdaptiveCruise, dt: float, model: PlantName) -> None:
        self.lateral = LateralPID(gains, model)
        self.cruise = cruise
        self.dt = dt
        self.fallbacks = 0
        self.solve_times: list[float] = []

    def reset(self) -> None:
        self.lateral.reset()
        self.cruise.reset()

    def step(self, state: EgoState, reference: Reference) -> Actuation:
        start = time.perf_counter()
        steering = self.lateral.update(state, reference, self.dt)
        acceleration = self.cruise.update(state.speed, reference.set_speed, reference.leaders, self.dt)
        self.solve_times.append(time.perf_counter() - start)
        return Actuation(acceleration=acceleration, steering=steering)


def make_controller(config: ControllerConfig, dt: float, plant: PlantName = "kinematic") -> Controller:
    """The controller `config.type` at a control period of `dt` [s] for a vehicle simulated as
    `plant` (the model a controller set to `plant` inverts); the MPC falls back to a PID tracker
    of its own."""
    gains = config.pid
    cruise = AdaptiveCruise(
        config.time_gap_s,
        config.standstill_gap_m,
        config.comfort_decel_mps2,
        gains.kp_speed,
        gains.ki_speed,
        gains.max_acceleration,
    )
    pid = PIDTracker(gains, cruise, dt, plant if gains.model == "plant" else gains.model)
    if config.type == "mpc":
        from controllers.mpc import MPCTracker

        settings = config.mpc
        if settings.model == "plant":
            settings = settings.model_copy(update={"model": plant})
        return MPCTracker(settings, dt, fallback=pid)
    return pid
