import math

import pytest

from controllers.cruise import AdaptiveCruise
from controllers.pid import PID
from controllers.reference import QuinticProfile, lane_keeping
from records import Neighbour


def test_quintic_lane_change_boundary_values_and_midpoint():
    profile = QuinticProfile(d0=12.0, d1=8.0, t0=1.0, duration=4.0)
    assert profile.sample(1.0) == pytest.approx((12.0, 0.0, 0.0))
    assert profile.sample(3.0)[0] == pytest.approx(10.0)
    assert profile.sample(3.0)[1] == pytest.approx(-4.0 * 1.875 / 4.0)  # peak rate 15/8 * delta / T
    assert profile.sample(5.0) == (8.0, 0.0, 0.0)
    assert profile.sample(9.0) == (8.0, 0.0, 0.0)


def test_quintic_from_a_moving_start_is_continuous():
    profile = QuinticProfile(d0=10.0, d1=12.0, t0=0.0, duration=3.0, v0=-0.8, a0=0.3)
    d, d_dot, d_ddot = profile.sample(0.0)
    assert (d, d_dot, d_ddot) == pytest.approx((10.0, -0.8, 0.3))
    assert profile.sample(3.0 - 1e-9) == pytest.approx((12.0, 0.0, 0.0), abs=1e-6)


def test_lane_keeping_is_constant():
    assert lane_keeping(4.0, 0.0).sample(7.0) == (4.0, 0.0, 0.0)


def test_pid_output_limits_and_clamp_anti_windup():
    pid = PID(kp=1.0, ki=1.0, limits=(-1.0, 1.0))
    for _ in range(100):
        assert pid.update(10.0, 0.1) == 1.0
    assert pid.integral < 1.0, "the integrator must not wind up while saturated"
    recovered = [pid.update(-0.5, 0.1) for _ in range(3)]
    assert recovered[0] < 1.0, "leaves saturation on the first tick the error changes sign"


def test_pid_rate_limit_and_reset():
    pid = PID(kp=1.0, rate_limit=2.0)
    assert pid.update(0.0, 0.1) == 0.0
    assert pid.update(5.0, 0.1) == pytest.approx(0.2)
    pid.reset()
    assert pid.update(5.0, 0.1) == 5.0


@pytest.mark.parametrize("bad", [{"kp": -1.0}, {"kp": math.nan}, {"kp": 1.0, "limits": (1.0, -1.0)}])
def test_pid_rejects_bad_gains(bad):
    with pytest.raises(ValueError, match="PID"):
        PID(**bad)


def test_cruise_never_brakes_beyond_comfort():
    cruise = AdaptiveCruise(time_gap=1.5, standstill_gap=8.0, comfort_deceleration=3.0)
    mild = cruise.update(25.0, 30.0, (Neighbour(gap=30.0, speed=22.0),), 1 / 15)
    assert -3.0 <= mild < 0.0
    cruise.reset()
    hard = cruise.update(30.0, 30.0, (Neighbour(gap=12.0, speed=10.0),), 1 / 15)
    assert hard == -3.0
    cruise.reset()
    assert cruise.update(20.0, 30.0, (), 1 / 15) == cruise.max_acceleration == 2.0
