"""Controllers from outside the package: a class by path or an installed entry point
(`common.plugins`), built for the run and checked against the `Controller` protocol."""

from __future__ import annotations

import math
from numbers import Real
from typing import Any

from common.plugins import CONTROLLER_GROUP, PluginError, bad_return, construct, failed_call, load_class
from controllers.config import ControllerConfig
from controllers.protocol import Controller
from records import Actuation, EgoState, PlantName, Reference

PROTOCOL = (
    "a controller: methods reset() and step(state, reference) -> Actuation, and attributes "
    "fallbacks (an int) and solve_times (a list of seconds)"
)


def plugin_controller(config: ControllerConfig, dt: float, plant: PlantName) -> Controller:
    """The controller class `config.type` names, built with whichever of `config` (the whole
    controller section), `dt` [s] and `plant` its constructor takes; PluginError (one line) when
    it does not load, build, or fit `PROTOCOL`."""
    cls = load_class(config.type, CONTROLLER_GROUP)
    controller = construct(cls, {"config": config, "dt": dt, "plant": plant}, config.type)
    missing = [name for name in ("reset", "step") if not callable(getattr(controller, name, None))]
    if not isinstance(getattr(controller, "fallbacks", None), int):
        missing.append("fallbacks")
    if not isinstance(getattr(controller, "solve_times", None), list):
        missing.append("solve_times")
    if missing:
        raise PluginError(f"{config.type}: not {PROTOCOL}; it lacks {', '.join(missing)}")
    return GuardedController(controller, config.type)


ACTUATION = "an Actuation of finite acceleration [m/s²] and steering [rad]"


class GuardedController:
    """A plug-in controller whose `step` and `reset` are checked at every call: an exception, or a
    step that returns anything but an `Actuation` of two finite real numbers, is `PluginFailed`
    naming the plug-in. `fallbacks`, `solve_times` and every other attribute are the plug-in's."""

    def __init__(self, controller: Controller, name: str) -> None:
        self.controller, self.name = controller, name

    @property
    def fallbacks(self) -> int:
        return self.controller.fallbacks

    @fallbacks.setter
    def fallbacks(self, count: int) -> None:
        self.controller.fallbacks = count

    @property
    def solve_times(self) -> list[float]:
        return self.controller.solve_times

    @solve_times.setter
    def solve_times(self, times: list[float]) -> None:
        self.controller.solve_times = times

    def reset(self) -> None:
        try:
            self.controller.reset()
        except (Exception, SystemExit) as error:  # noqa: BLE001 - user code may raise or exit
            raise failed_call(self.name, "reset", error) from None

    def step(self, state: EgoState, reference: Reference) -> Actuation:
        try:
            actuation = self.controller.step(state, reference)
        except (Exception, SystemExit) as error:  # noqa: BLE001 - user code may raise or exit
            raise failed_call(self.name, "step", error) from None
        values = (getattr(actuation, "acceleration", None), getattr(actuation, "steering", None))
        if not isinstance(actuation, Actuation) or not all(
            isinstance(v, Real) and not isinstance(v, bool) and math.isfinite(v) for v in values
        ):
            raise bad_return(self.name, "step", actuation, ACTUATION)
        return actuation

    def __getattr__(self, name: str) -> Any:
        return getattr(self.controller, name)
