"""Control layer: the plant model, lane changes against the targets, MPC bounds and fallback,
golden trajectories, the python-control check of the lateral design."""

import time
from pathlib import Path

import casadi as ca
import control
import numpy as np
import pytest
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle
from pydantic import ValidationError

from controllers.bicycle import BicycleState, lateral_acceleration, step, symbolic_lane_model
from controllers.config import MPCSettings, PIDGains
from controllers.cruise import AdaptiveCruise
from controllers.lateral import closed_loop, dynamic_loop
from controllers.mpc import MPCTracker
from controllers.reference import lane_change
from controllers.tracker import PIDTracker
from records import Actuation, EgoState, Reference
from stack.apps.track import run_maneuver
from stack.settings.run import ConfigError, ControllerConfig, build_config
from stack.sim.empty_road import EmptyRoad

GOLDEN = Path(__file__).parent / "golden" / "lane_change.npz"
DT = 1 / 15


def test_bicycle_matches_highway_env_vehicle_step():
    road = Road(RoadNetwork.straight_road_network(3))
    vehicle = Vehicle(road, [10.0, 4.0], 0.01, 25.0)
    state = BicycleState(10.0, 4.0, 0.01, 25.0)
    rng = np.random.default_rng(0)
    for _ in range(300):
        acceleration, steering = rng.uniform(-3, 3), rng.uniform(-0.1, 0.1)
        vehicle.act({"acceleration": acceleration, "steering": steering})
        vehicle.step(DT)
        state = step(state, acceleration, steering, DT)
        assert (
            np.abs(
                [
                    vehicle.position[0] - state.x,
                    vehicle.position[1] - state.y,
                    vehicle.heading - state.psi,
                    vehicle.speed - state.v,
                ]
            ).max()
            <= 1e-9
        )


def test_symbolic_model_equals_the_pure_function_on_a_straight_lane():
    model = symbolic_lane_model()
    state = BicycleState(0.0, 1.5, 0.02, 20.0)
    for acceleration, steering in [(1.0, 0.05), (-2.0, -0.1), (0.0, 0.0)]:
        after = step(state, acceleration, steering, DT)
        symbolic = np.array(
            model(ca.DM([state.y, state.psi, state.v]), ca.DM([acceleration, steering]), 0.0, DT)
        )
        np.testing.assert_allclose(symbolic.ravel(), [after.y, after.psi, after.v], atol=1e-12)
        state = after


@pytest.mark.parametrize("controller", ["pid", "mpc"])
@pytest.mark.parametrize("speed", [15.0, 30.0])
@pytest.mark.parametrize("direction", ["left", "right"])
def test_lane_change_meets_the_targets(controller, speed, direction):
    m = run_maneuver(controller, ControllerConfig(), "straight", "kinematic", speed, direction, 5.0, DT)
    assert 3.5 <= m.duration_s <= 5.0
    assert m.overshoot_m <= 0.02
    assert m.peak_lat_accel <= 2.0
    assert m.peak_lat_jerk <= 2.5
    assert m.rms_error_m <= (0.03 if controller == "pid" else 0.01)
    assert m.fallbacks == 0
    assert abs(m.trace["d"][-1]) == pytest.approx(4.0, abs=0.02)


TARGETS = {
    ("pid", "kinematic"): (0.02, 0.03),
    ("pid", "dynamic"): (0.03, 0.04),
    ("mpc", "kinematic"): (0.02, 0.01),
    ("mpc", "dynamic"): (0.03, 0.02),
}
"""(overshoot, RMS) bounds per controller and plant [m] (the control issue's targets)."""


@pytest.mark.parametrize("controller", ["pid", "mpc"])
@pytest.mark.parametrize("plant", ["kinematic", "dynamic"])
@pytest.mark.parametrize(
    ("road", "speeds"), [("straight", (10.0, 35.0)), ("bend-1000", (22.0, 35.0)), ("bend-500", (25.0,))]
)
def test_the_controllers_meet_the_targets_on_both_plants_and_on_bends(controller, plant, road, speeds):
    overshoot, rms = TARGETS[(controller, plant)]
    for speed in speeds:
        for direction in ("left", "right"):
            m = run_maneuver(controller, ControllerConfig(), road, plant, speed, direction, 5.0, DT)
            assert m.duration_s is not None and 3.5 <= m.duration_s <= 5.0, (speed, direction)
            assert m.overshoot_m <= overshoot and m.rms_error_m <= rms, (speed, direction)
            assert m.peak_lat_accel <= 2.0 and m.peak_lat_jerk <= 2.5, (speed, direction)
            assert m.fallbacks == 0, (speed, direction)


def test_a_car_on_a_bend_starts_in_steady_cornering():
    """The empty road starts the dynamic bicycle in the steady turn: with the steady steering
    (L r / v) its yaw rate, sideslip and course along the lane stay as they are."""
    road = EmptyRoad("bend-500", "dynamic", 25.0, DT)
    start = road.reset().ego_state()
    assert start.yaw_rate == pytest.approx(25.0 / 504.0, rel=1e-2)
    assert start.d_dot == pytest.approx(0.0, abs=1e-9)
    for _ in range(30):
        after = road.step(Actuation(0.0, 5.0 * start.yaw_rate / 25.0)).ego_state()
    assert after.yaw_rate == pytest.approx(start.yaw_rate, rel=1e-3)
    assert after.lateral_speed == pytest.approx(start.lateral_speed, rel=1e-2)
    assert abs(after.d - start.d) < 0.01


@pytest.mark.parametrize("speed", [10.0, 22.0, 35.0])
def test_the_pid_design_on_the_linearised_dynamic_bicycle(speed):
    """python-control: the loop e -> d of the PID with its yaw lead on the linear tyre model is
    stable with a phase margin of at least 30 deg and no gain limit at 10, 22 and 35 m/s."""
    loop = dynamic_loop(PIDGains(), speed)
    assert np.all(control.poles(control.feedback(loop, 1)).real < 0)
    gain_margin, phase_margin, _, _ = control.margin(loop)
    assert phase_margin >= 30.0 and gain_margin > 10.0


def test_builtin_baseline_is_far_outside_comfort():
    m = run_maneuver("builtin", ControllerConfig(), "straight", "kinematic", 25.0, "left", 5.0, DT)
    assert m.duration_s < 2.5 and m.peak_lat_accel > 6.0 and m.peak_lat_jerk > 15.0


def test_mpc_respects_steering_rate_and_lateral_acceleration_bounds():
    settings = MPCSettings(max_steering_rate=0.2, max_lateral_acceleration=1.0)
    m = run_maneuver("mpc", ControllerConfig(mpc=settings), "straight", "kinematic", 30.0, "left", 5.0, DT)
    steering = np.array(m.trace["steering"])
    assert np.abs(np.diff(steering)).max() <= 0.2 * DT + 1e-6
    assert max(abs(lateral_acceleration(30.0, s)) for s in steering) <= 1.0 + 1e-3
    assert np.abs(steering).max() <= settings.max_steering


def make_mpc(settings: MPCSettings) -> MPCTracker:
    fallback = PIDTracker(PIDGains(), AdaptiveCruise(1.5, 8.0, 3.0), DT, "kinematic")
    return MPCTracker(settings, DT, fallback)


@pytest.mark.parametrize(
    "starving", [{"solver": "sqp", "max_iterations": 1}, {"solver": "rti", "max_qp_iterations": 1}]
)
def test_failed_solves_fall_back_and_never_give_nan(starving):
    state = EgoState(d=0.3, heading=0.01, speed=25.0)
    reference = Reference(1.0, 0.5, 0.0, set_speed=25.0)
    starved = make_mpc(MPCSettings.model_validate(starving))
    actuation = starved.step(state, reference)
    assert starved.status != "Solve_Succeeded" and starved.fallbacks == 1
    assert np.isfinite([actuation.acceleration, actuation.steering]).all()
    poisoned = make_mpc(MPCSettings())
    bad = Reference(float("nan"), 0.0, 0.0, set_speed=25.0)
    actuation = poisoned.step(state, bad)
    assert poisoned.fallbacks == 1 and np.isfinite([actuation.acceleration, actuation.steering]).all()
    healthy = make_mpc(MPCSettings())
    healthy.step(state, reference)
    assert healthy.status == "Solve_Succeeded" and healthy.fallbacks == 0 and healthy.solve_time > 0


def test_a_slow_machine_changes_no_decision_only_the_reported_time(monkeypatch):
    """Fallbacks come from the solver's outcome, not the clock: an artificially slowed solve (every
    call 60 ms, beyond `max_solve_ms`) drives exactly as a fast one and is reported as slow."""
    state, reference = EgoState(d=0.3, heading=0.01, speed=25.0), Reference(1.0, 0.5, 0.0, set_speed=25.0)
    fast, slow = make_mpc(MPCSettings()), make_mpc(MPCSettings())
    solver = slow.solver

    def sluggish(*args):
        time.sleep(0.06)
        return solver(*args)

    monkeypatch.setattr(slow, "solver", sluggish)
    monkeypatch.setattr(sluggish, "stats", solver.stats, raising=False)
    for _ in range(3):
        assert fast.step(state, reference) == slow.step(state, reference)
    assert slow.fallbacks == fast.fallbacks == 0
    assert slow.slow_solves == 3 and min(slow.solve_times) >= 0.06


def golden_traces() -> dict[str, np.ndarray]:
    return {
        name: np.array(
            run_maneuver(name, ControllerConfig(), "straight", "kinematic", 25.0, "left", 5.0, DT).trace["d"]
        )
        for name in ("pid", "mpc")
    }


def test_golden_lane_change_trajectories():
    """Regression: the lateral offset of a 25 m/s left lane change, tick by tick. Regenerate with
    `python -c "from tests.test_controllers import write_golden; write_golden()"` after an
    intended change."""
    golden = np.load(GOLDEN, allow_pickle=False)
    for name, trace in golden_traces().items():
        np.testing.assert_allclose(trace, golden[name], atol=1e-6, err_msg=name)


def write_golden() -> None:
    np.savez(GOLDEN, **golden_traces())


def test_lateral_design_poles_and_step_response():
    for speed in (15.0, 30.0):
        loop = closed_loop(PIDGains(), speed)
        poles = control.poles(loop)
        assert np.all(poles.real < 0)
        np.testing.assert_allclose(
            sorted(poles, key=lambda p: (p.real, p.imag)), [-2.82 - 1.42j, -2.82 + 1.42j, -0.36], atol=0.01
        )
        info = control.step_info(loop)
        assert info["RiseTime"] < 0.7 and info["Overshoot"] < 14.0


def test_unreachable_lane_and_bad_settings_are_refused():
    with pytest.raises(ValueError, match="target lane 4 is not reachable from lane 3"):
        lane_change([0.0, 4.0, 8.0, 12.0], 3, 4, 12.0, 0.0, 5.0)
    with pytest.raises(ValueError, match="not reachable"):
        lane_change([0.0, 4.0, 8.0], 0, 2, 0.0, 0.0, 5.0)
    for bad, key in [
        ({"pid": {"kp_lateral": -1}}, "controller.pid.kp_lateral"),
        ({"pid": {"ki_speed": float("nan")}}, "controller.pid.ki_speed"),
        ({"mpc": {"horizon": 0}}, "controller.mpc.horizon"),
        ({"mpc": {"max_lateral_acceleration": -2}}, "controller.mpc.max_lateral_acceleration"),
    ]:
        with pytest.raises(ConfigError, match=key):
            build_config({"controller": bad})
    with pytest.raises(ValidationError):
        MPCSettings(horizon=0)
