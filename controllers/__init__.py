"""The control layer: the lane-change maneuver (a reference to follow) and the controllers that
track it with steering and throttle (`make_controller`: PID + adaptive cruise, or MPC). Imported on
first use: python-control and CasADi are heavy, and the configs only need `controllers.config`."""

from importlib import import_module
from typing import Any

import common.numba_cache  # noqa: F401  numba's cache folder is set before anything here compiles

_PUBLIC = {
    "ControllerConfig": "controllers.config",
    "Maneuver": "controllers.maneuver",
    "Controller": "controllers.protocol",
    "make_controller": "controllers.tracker",
}
__all__ = list(_PUBLIC)


def __getattr__(name: str) -> Any:
    if name in _PUBLIC:
        return getattr(import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'controllers' has no attribute {name!r}")
