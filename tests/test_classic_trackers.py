"""The classic trackers (pure pursuit, Stanley, LQR) on highway-env's kinematic bicycle."""

import math

import numpy as np
import pytest
import scipy.linalg

from controllers.bicycle import BicycleState, slip_angle, step
from controllers.config import ControllerConfig, LQRSettings
from controllers.lqr import LateralLQR, error_model, weights
from controllers.tracker import make_controller
from records import EgoState, Reference

CLASSIC = ("pure-pursuit", "stanley", "lqr")
DT = 1 / 15


def drive(name: str, speed: float, offset: float, seconds: float = 10.0) -> tuple[list[float], list[float]]:
    """(lateral offsets [m], steering [rad]) of the tracker `name` holding d = `offset` on a
    straight road (the lane frame is the world frame), from the lane centre at `speed`."""
    controller = make_controller(ControllerConfig(type=name), DT, "kinematic")
    controller.reset()
    car, offsets, steering = BicycleState(0.0, 0.0, 0.0, speed), [], []
    reference = Reference(d=offset, d_dot=0.0, d_ddot=0.0, set_speed=speed)
    last = 0.0
    for _ in range(round(seconds / DT)):
        yaw_rate = speed * math.sin(slip_angle(last)) / 2.5
        state = EgoState(d=car.y, heading=car.psi, speed=car.v, yaw_rate=yaw_rate)
        actuation = controller.step(state, reference)
        last = actuation.steering
        car = step(car, actuation.acceleration, actuation.steering, DT)
        offsets.append(car.y)
        steering.append(actuation.steering)
    return offsets, steering


@pytest.mark.parametrize("name", CLASSIC)
@pytest.mark.parametrize("speed", [5.0, 20.0, 35.0])
def test_converges_to_a_lateral_offset(name, speed):
    offsets, _ = drive(name, speed, 0.5)
    assert offsets[-1] == pytest.approx(0.5, abs=0.01)
    assert max(offsets) < 0.5 + 0.1


@pytest.mark.parametrize("name", CLASSIC)
def test_steering_stays_within_its_angle_and_rate_limits(name):
    _, steering = drive(name, 10.0, 30.0, seconds=4.0)
    limits = ControllerConfig().lqr
    assert max(abs(s) for s in steering) <= limits.max_steering + 1e-12
    rates = np.abs(np.diff([0.0, *steering])) / DT
    assert rates.max() <= limits.steering_rate + 1e-9


def test_lqr_gains_from_python_control_match_the_riccati_equation_by_hand():
    settings, speed = LQRSettings(), 20.0
    a, b = error_model(speed, DT)
    q, r = weights(settings)
    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    by_hand = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a).reshape(-1)
    lqr = LateralLQR(settings, DT)
    assert lqr.gain(speed) == pytest.approx(by_hand, rel=1e-6)
    assert lqr.gain(20.5) == pytest.approx((lqr.gain(20.0) + lqr.gain(21.0)) / 2)


def test_lqr_closed_loop_is_stable_at_every_scheduled_speed():
    lqr = LateralLQR(LQRSettings(), DT)
    for speed, gain in zip(lqr.speeds, lqr.gains, strict=True):
        a, b = error_model(speed, DT)
        assert np.abs(np.linalg.eigvals(a - b @ gain[None, :])).max() < 1.0
