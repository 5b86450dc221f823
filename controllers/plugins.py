"""Controllers from outside the package: a class by path or an installed entry point
(`records.plugins`), built for the run and checked against the `Controller` protocol."""

from __future__ import annotations

from controllers.config import ControllerConfig
from controllers.protocol import Controller
from records import PlantName
from records.plugins import CONTROLLER_GROUP, PluginError, construct, load_class

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
    return controller
