"""The control layer: the lane-change maneuver (a reference to follow) and the controllers that
track it with steering and throttle (`make_controller`: PID + adaptive cruise, or MPC)."""

from controllers.config import ControllerConfig
from controllers.maneuver import Maneuver
from controllers.tracker import Controller, make_controller

__all__ = ["Controller", "ControllerConfig", "Maneuver", "make_controller"]
