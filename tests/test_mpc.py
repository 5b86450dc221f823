"""The MPC's solvers and models: sqpmethod + qrqp against an IPOPT reference on a recorded lane
change, the dynamic prediction model against highway-env's BicycleVehicle, soft comfort bounds that
never make a solve infeasible, and bad solver, model and parameter names refused in one line."""

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.dynamics import BicycleVehicle
from typer.testing import CliRunner

from controllers.casadi_codegen import compiled, compiler
from controllers.config import MPCSettings, PIDGains
from controllers.cruise import AdaptiveCruise
from controllers.mpc import MPCTracker
from controllers.mpc_problem import build_problem, prediction_model
from controllers.tracker import PIDTracker
from records import EgoState, Reference
from stack.apps.cli import app
from stack.apps.track import run_maneuver
from stack.settings.run import ControllerConfig

DT = 1 / 15


def recorded_solves(settings: MPCSettings, monkeypatch) -> list[tuple[np.ndarray, ...]]:
    """The solver arguments of every tick of a 25 m/s lane change on the plant of the model."""
    calls: list[tuple[np.ndarray, ...]] = []
    monkeypatch.setattr(MPCTracker, "recording", calls)
    config = ControllerConfig(mpc=settings)
    maneuver = run_maneuver("mpc", config, "straight", settings.model, 25.0, "left", 5.0, DT)
    assert maneuver.fallbacks == 0
    return calls


@pytest.mark.parametrize("solver", ["rti", "sqp"])
@pytest.mark.parametrize("model", ["kinematic", "dynamic"])
def test_first_move_matches_an_ipopt_reference_on_a_recorded_lane_change(model, solver, monkeypatch):
    """Each tick of a lane change driven by `solver`, replayed: its first steering move within
    1e-3 rad of IPOPT's converged one from the same start and warm start."""
    settings = MPCSettings(model=model, solver=solver)
    calls = recorded_solves(settings, monkeypatch)
    fast = build_problem(settings, DT)
    ipopt = build_problem(settings.model_copy(update={"solver": "ipopt"}), DT)
    for arguments in calls:
        moves = []
        for problem in (fast, ipopt):
            w = np.array(problem.solver(*arguments)[0]).ravel()
            assert problem.solver.stats()["success"]
            moves.append(problem.unpack(w)[0][1, 0])
        assert abs(moves[0] - moves[1]) <= 1e-3


def lane_state(vehicle: BicycleVehicle) -> list[float]:
    """(d, psi, v, v_y, r) of a vehicle on a straight road along x: d = y."""
    return [vehicle.position[1], vehicle.heading, vehicle.speed, vehicle.lateral_speed, vehicle.yaw_rate]


def test_dynamic_model_steps_as_highway_env_bicycle_vehicle():
    settings = MPCSettings()
    assert settings.mass == BicycleVehicle.MASS
    assert settings.yaw_inertia == pytest.approx(BicycleVehicle.INERTIA_Z, rel=1e-12)
    assert settings.cornering_stiffness_front == 2 * BicycleVehicle.FRICTION_FRONT
    assert settings.cornering_stiffness_rear == 2 * BicycleVehicle.FRICTION_REAR
    model, _ = prediction_model(settings.model_copy(update={"model": "dynamic"}))
    vehicle = BicycleVehicle(Road(RoadNetwork.straight_road_network(3)), [10.0, 4.0], 0.01, 25.0)
    rng = np.random.default_rng(0)
    for _ in range(100):
        acceleration, steering = rng.uniform(-3, 3), rng.uniform(-0.1, 0.1)
        before = lane_state(vehicle)
        vehicle.act({"acceleration": acceleration, "steering": steering})
        vehicle.step(DT)
        predicted = np.array(model(ca.DM(before), ca.DM([acceleration, steering]), 0.0, DT)).ravel()
        np.testing.assert_allclose(predicted, lane_state(vehicle), atol=1e-10)


def test_an_infeasible_comfort_bound_is_softened_not_a_fallback():
    """Already yawing at 0.1 rad/s at 30 m/s (a_y = 3 m/s^2) with a 0.2 m/s^2 bound: no input meets
    the hard bound at the first step, the slack does."""
    fallback = PIDTracker(PIDGains(), AdaptiveCruise(1.5, 8.0, 3.0), DT, "kinematic")
    for model in ("kinematic", "dynamic"):
        settings = MPCSettings(model=model, max_lateral_acceleration=0.2, max_steering_rate=0.01)
        tracker = MPCTracker(settings, DT, fallback)
        tracker.last_input = np.array([0.0, 0.05])
        state = EgoState(d=0.5, heading=0.05, speed=30.0, lateral_speed=0.3, yaw_rate=0.1)
        actuation = tracker.step(state, Reference(4.0, 0.0, 0.0, set_speed=30.0))
        assert tracker.fallbacks == 0 and tracker.status == "Solve_Succeeded", model
        assert np.isfinite([actuation.acceleration, actuation.steering]).all()


@pytest.mark.parametrize(
    ("setting", "key"),
    [
        ("controller.mpc.solver=osqp", "controller.mpc.solver"),
        ("controller.mpc.model=unicycle", "controller.mpc.model"),
        ("controller.mpc.cornering_stiffness_front=0", "controller.mpc.cornering_stiffness_front"),
        ("controller.mpc.yaw_inertia=-1", "controller.mpc.yaw_inertia"),
        ("controller.mpc.horizon=0", "controller.mpc.horizon"),
    ],
)
def test_bad_mpc_names_and_parameters_are_one_line_exit_2(setting, key, tmp_path: Path):
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["track", "--set", setting, "--out", str(out), "--no-progress"])
    assert result.exit_code == 2
    assert len(result.output.strip().splitlines()) == 1 and key in result.output
    assert not out.exists()


def test_the_compiled_linearisation_equals_the_interpreted_one_bit_for_bit(monkeypatch, tmp_path: Path):
    """A machine without a compiler runs the interpreted function and drives exactly the same."""
    monkeypatch.setenv("DRIVESTACK_CACHE", str(tmp_path))
    model, _ = prediction_model(MPCSettings(model="dynamic"))
    state, control = ca.SX.sym("x", 5), ca.SX.sym("u", 2)
    function = ca.Function(
        "step_jacobian", [state, control], [ca.jacobian(model(state, control, 1e-3, DT), state)]
    )
    fast = compiled(function)
    assert fast.is_a("External") == (compiler() is not None)
    with monkeypatch.context() as no_compiler:
        no_compiler.setattr("controllers.casadi_codegen.shutil.which", lambda name: None)
        assert compiled(function) is function
    monkeypatch.setenv("DRIVESTACK_COMPILE", "0")
    assert compiled(function) is function
    rng = np.random.default_rng(0)
    for _ in range(20):
        x, u = rng.uniform([0, -0.1, 5, -1, -0.2], [4, 0.1, 35, 1, 0.2]), rng.uniform(-0.3, 0.3, 2)
        assert np.array_equal(np.array(fast(x, u)), np.array(function(x, u)))


@pytest.mark.slow
@pytest.mark.skipif(compiler() is None, reason="no C compiler on this machine")
def test_a_machine_without_a_compiler_drives_exactly_the_same(monkeypatch, tmp_path: Path):
    """A whole lane change, compiled and interpreted (slow: it compiles the MPC; the default suite
    compares the compiled linearisation with the interpreted one bit for bit, above)."""
    monkeypatch.setenv("DRIVESTACK_CACHE", str(tmp_path))
    traces = []
    for setting in ("1", "0"):
        monkeypatch.setenv("DRIVESTACK_COMPILE", setting)
        build_problem.cache_clear()
        m = run_maneuver("mpc", ControllerConfig(), "bend-1000", "dynamic", 35.0, "left", 5.0, DT)
        traces.append(np.array(m.trace["steering"]))
    build_problem.cache_clear()
    assert np.array_equal(traces[0], traces[1])
