"""Controllers behind one verb, `step(state, reference) -> Actuation` (the `Controller` protocol),
built by name: PID, MPC, the classic trackers (pure pursuit, Stanley, LQR) or a plug-in
(`common.plugins`)."""

from __future__ import annotations

import time
from typing import Protocol

from controllers.config import ControllerConfig, PIDGains
from controllers.cruise import AdaptiveCruise
from controllers.lateral import LateralPID
from controllers.protocol import Controller
from records import CONTROLLER_NAMES, Actuation, EgoState, PlantName, Reference


class LateralLaw(Protocol):
    """A steering law: `update` gives the steering [rad] for one tick of `dt` [s]."""

    def reset(self) -> None: ...

    def update(self, state: EgoState, reference: Reference, dt: float) -> float: ...


class SteeringTracker:
    """A lateral law for steering, adaptive cruise for throttle, at a control period of `dt` [s]."""

    def __init__(self, lateral: LateralLaw, cruise: AdaptiveCruise, dt: float) -> None:
        self.lateral = lateral
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


class PIDTracker(SteeringTracker):
    """Lateral PID for steering, adaptive cruise for throttle, at a control period of `dt` [s]."""

    def __init__(self, gains: PIDGains, cruise: AdaptiveCruise, dt: float, model: PlantName) -> None:
        super().__init__(LateralPID(gains, model), cruise, dt)


def make_controller(config: ControllerConfig, dt: float, plant: PlantName = "kinematic") -> Controller:
    """The controller `config.type` at a control period of `dt` [s] for a vehicle simulated as
    `plant` (the model a controller set to `plant` inverts); the MPC falls back to a PID tracker
    of its own. A name not built in is a plug-in (`controllers.plugins`)."""
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
    if config.type == "pure-pursuit":
        from controllers.pure_pursuit import PurePursuit

        return SteeringTracker(PurePursuit(config.pure_pursuit), cruise, dt)
    if config.type == "stanley":
        from controllers.stanley import Stanley

        return SteeringTracker(Stanley(config.stanley), cruise, dt)
    if config.type == "lqr":
        from controllers.lqr import LateralLQR

        return SteeringTracker(LateralLQR(config.lqr, dt), cruise, dt)
    if config.type not in CONTROLLER_NAMES:
        from controllers.plugins import plugin_controller

        return plugin_controller(config, dt, plant)
    return pid
