"""Driver populations (`stack.sim.drivers`): each traffic driver draws its IDM and MOBIL parameters at
spawn from the env's seeded generator; `highway-env` draws nothing. The same seed gives the same
drivers; stock highway-env (which reads each vehicle's own attributes), the `vector` road and the
batch drive them alike, bit for bit; a batched run is the per-world run episode for episode; the
config and `--traffic` refuse what is not a population in one line."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from highway_env.vehicle.behavior import IDMVehicle
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.runs.batch_episodes import batch_refusal, run_batched
from stack.runs.episodes import run, run_episode
from stack.settings.run import ConfigError, build_config, drivers_of, in_scenario
from stack.sim.drivers import KEY_LIMIT, draw_driver, draws_nothing
from stack.sim.envs import VECTOR_HIGHWAY
from stack.sim.highway import env_config
from stack.worlds.drivers import (
    DRIVER_PARAMETERS,
    HABIT_PARAMETERS,
    POPULATION_RANGES,
    POPULATIONS,
    LogNormal,
    limits,
    population_shares,
)
from tests.test_batched_episodes import assert_same_episodes
from tests.test_sim_backends import assert_identical
from tests.test_sim_batched import assert_worlds_identical

STOCK_MIX = {"highway-env": 0.3, "calibrated": 0.4, "aggressive": 0.3}
"""Shares of the populations stock highway-env drives (no habits)."""
DRAWN = ("TIME_WANTED", "COMFORT_ACC_MAX", "COMFORT_ACC_MIN", "POLITENESS", "LANE_CHANGE_MAX_BRAKING_IMPOSED")


def highway_in(scenario: str, drivers: object):
    return build_config({}, scenario=scenario, traffic=drivers).highway


def drawn_drivers(scenario: str, drivers: object, seed: int) -> np.ndarray:
    """Every IDM driver's target speed and drawn attributes after a reset with `seed`."""
    env = gym.make(VECTOR_HIGHWAY, config=env_config(highway_in(scenario, drivers)), disable_env_checker=True)
    env.reset(seed=seed)
    rows = [
        [v.target_speed, *(getattr(v, name) for name in DRAWN)]
        for v in env.unwrapped.road.vehicles
        if isinstance(v, IDMVehicle)
    ]
    env.close()
    return np.array(rows)


def test_highway_env_drivers_draw_nothing_and_keep_the_class_constants():
    drivers = drawn_drivers("overtaking", "highway-env", seed=3)
    constants = [IDMVehicle.TIME_WANTED, IDMVehicle.COMFORT_ACC_MAX, IDMVehicle.COMFORT_ACC_MIN]
    np.testing.assert_array_equal(drivers[:, 1:4], np.tile(constants, (len(drivers), 1)))
    assert draws_nothing(None) and draws_nothing("highway-env") and not draws_nothing("mixed")


@pytest.mark.parametrize("population", ["calibrated", "aggressive", "cautious"])
def test_each_driver_draws_its_parameters_within_the_populations_ranges(population):
    drivers = drawn_drivers("overtaking", population, seed=4)
    ranges = POPULATION_RANGES[population]
    for column, name in ((1, "time_gap_s"), (2, "max_acceleration"), (4, "politeness")):
        low, high = limits(getattr(ranges, name))
        assert ((low <= drivers[:, column]) & (drivers[:, column] <= high)).all(), name
    low, high = limits(ranges.comfortable_deceleration)
    assert ((low <= -drivers[:, 3]) & (-drivers[:, 3] <= high)).all()
    if limits(ranges.time_gap_s)[0] < limits(ranges.time_gap_s)[1]:
        assert len(set(drivers[:, 1].tolist())) == len(drivers), "each driver draws its own"


CALIBRATED_MEDIANS = {
    "time_gap_s": 0.96,
    "max_acceleration": 1.05,
    "comfortable_deceleration": 1.51,
    "jam_clearance_m": 3.77,
}
"""The population medians of Zhang and Sun's hierarchical calibration of IDM on highD (docs/traffic.md)."""


def test_the_calibrated_drivers_are_log_normal_around_the_sources_medians():
    """400 drivers: each IDM parameter's sample median and log standard deviation are the
    source's median and the stated spread (0.2), within sampling error, and inside the truncation."""
    ranges = POPULATION_RANGES["calibrated"]
    rng = np.random.default_rng(1015000)
    drawn = [draw_driver(rng, ["calibrated"], np.ones(1)).values for _ in range(400)]
    for name, median in CALIBRATED_MEDIANS.items():
        spread = getattr(ranges, name)
        assert isinstance(spread, LogNormal) and spread.median == median
        values = np.array([driver[name] for driver in drawn])
        assert ((spread.low <= values) & (values <= spread.high)).all(), name
        assert np.median(values) == pytest.approx(median, rel=0.05), name
        assert np.log(values).std() == pytest.approx(spread.log_std, rel=0.15), name
    politeness = np.array([driver["politeness"] for driver in drawn])
    assert politeness.mean() == pytest.approx(0.25, abs=0.03) and politeness.max() <= 0.5


def test_the_calibrated_draw_is_the_same_per_seed_and_the_other_populations_draw_as_before():
    """One uniform draw per parameter, whatever the distribution: the same seed, the same drivers;
    a population of uniform ranges draws exactly `rng.uniform(lows, highs)` (then its habits' and
    its key), and leaves the generator where those calls leave it."""
    one = [draw_driver(np.random.default_rng(1015001), ["calibrated"], np.ones(1)) for _ in range(2)]
    assert one[0] == one[1]
    rng, again = np.random.default_rng(1015002), np.random.default_rng(1015002)
    aggressive = POPULATION_RANGES["aggressive"]
    lows, highs = zip(*(limits(getattr(aggressive, name)) for name in DRIVER_PARAMETERS), strict=True)
    expected = again.uniform(lows, highs).tolist()
    assert list(draw_driver(rng, ["aggressive"], np.ones(1)).values.values()) == expected
    assert rng.random() == again.random(), "the draw takes as much of the stream as rng.uniform"
    distracted = POPULATION_RANGES["distracted"]
    drawn = draw_driver(rng, ["distracted"], np.ones(1))
    again.random(len(DRIVER_PARAMETERS))
    habit_lows, habit_highs = zip(*(getattr(distracted, name) for name in HABIT_PARAMETERS), strict=True)
    expected = again.uniform(habit_lows, habit_highs).tolist()
    assert [drawn.values[name] for name in HABIT_PARAMETERS] == expected
    assert drawn.key == int(again.integers(0, KEY_LIMIT)) and rng.random() == again.random()


def test_the_aggressive_drivers_are_the_issues():
    aggressive = POPULATION_RANGES["aggressive"]
    assert aggressive.time_gap_s == (0.6, 1.0) and aggressive.politeness == (0.0, 0.0)
    assert aggressive.safe_braking == (4.0, 4.0)
    assert aggressive.decision_period_s[1] < IDMVehicle.LANE_CHANGE_DELAY, "weaves more often"


def test_the_same_seed_draws_the_same_drivers_and_another_seed_others():
    one, again = drawn_drivers("dense", "mixed", seed=9), drawn_drivers("dense", "mixed", seed=9)
    np.testing.assert_array_equal(one.view(np.uint64), again.view(np.uint64))
    assert not np.array_equal(one, drawn_drivers("dense", "mixed", seed=10))
    mixed_time_gaps = set(one[:, 1].tolist())
    assert IDMVehicle.TIME_WANTED in mixed_time_gaps and len(mixed_time_gaps) > 2, "shares of several"


@pytest.mark.parametrize("population", ["calibrated", "aggressive", STOCK_MIX])
def test_the_vector_road_drives_the_drivers_as_stock_does_bit_for_bit(population):
    """Stock highway-env's `IDMVehicle` reads each driver's own attributes: the vector road's
    arrays must give the very same trajectories (lane changes, crashes of the ramming ego)."""
    states = assert_identical(highway_in("overtaking", population), seed=21, frames=150, backend="vector")
    assert len(states) == 150


def test_the_fast_road_drives_the_drivers_as_stock_does_bit_for_bit():
    assert_identical(highway_in("dense", STOCK_MIX), seed=22, frames=120, backend="fast")


@pytest.mark.parametrize(
    ("scenario", "population"), [("overtaking", "aggressive"), ("dense", "mixed"), ("dense", "calibrated")]
)
def test_each_batched_world_is_the_vector_world_under_a_population(scenario, population):
    assert_worlds_identical(highway_in(scenario, population), [3, 4], frames=120)


def test_a_batched_run_is_the_per_world_run_under_a_population():
    config = build_config(
        {},
        "test",
        seed=990500,
        episodes=3,
        scenario="overtaking",
        traffic="aggressive",
        planner__agent="mobil",
    )
    assert batch_refusal(config) is None
    batched = run_batched(config, [0, 1, 2])
    assert_same_episodes(batched, [run_episode(config, e) for e in range(3)])
    assert any(e.lane_changes for e in batched)


def test_shares_name_populations_and_sum_to_one():
    assert population_shares({"calibrated": 0.5, "mixed": 0.5})["calibrated"] == pytest.approx(0.625)
    with pytest.raises(ValueError, match="sum to 1"):
        population_shares({"calibrated": 0.5})
    with pytest.raises(ValueError, match="unknown driver population 'wild'"):
        population_shares("wild")
    assert set(POPULATIONS) >= {"highway-env", "calibrated", "aggressive", "cautious", "mixed"}
    assert DRIVER_PARAMETERS[0] == "desired_speed_factor"


def test_a_population_in_a_config_file_key_and_on_the_command_line():
    data = {"scenario": "jam", "highway": {"traffic": {"drivers": "cautious"}}}
    assert build_config(data).highway.traffic.drivers == "cautious"
    assert (
        build_config({}, scenario="random", traffic="calibrated").highway.random_traffic.drivers
        == "calibrated"
    )
    with pytest.raises(ConfigError, match="--traffic: highway.traffic.drivers: unknown driver population"):
        build_config({}, scenario="jam", traffic="wild", labels={"traffic": "--traffic"})
    assert build_config({}, traffic="aggressive").highway.traffic.classes is None
    assert build_config({}, traffic="highway-env").highway.traffic is None
    with pytest.raises(ConfigError, match="classes: ego_position"):
        build_config({"highway": {"traffic": {"drivers": "cautious", "ego_position": 0.5}}})


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("wild", "unknown driver population 'wild'"),
        ("calibrated=x", "expected NAME=SHARE"),
        ("calibrated=0.4", "sum to 1"),
    ],
)
def test_traffic_option_errors_are_one_line(value, message):
    result = CliRunner().invoke(app, ["run", "--scenario", "jam", "--traffic", value, "--episodes", "1"])
    assert result.exit_code == 2
    assert message in result.output and "Traceback" not in result.output


def test_a_world_moved_to_another_scenario_keeps_its_drivers():
    """`benchmark` and a training mix move the config to each scenario: the drivers go along."""
    config = build_config({}, traffic={"calibrated": 0.6, "cautious": 0.4})
    for scenario in ("jam", "random", "dense"):
        assert drivers_of(in_scenario(config, scenario).highway) == {"calibrated": 0.6, "cautious": 0.4}
    assert drivers_of(in_scenario(build_config({}), "jam").highway) == "highway-env"


@pytest.mark.parametrize("command", [["benchmark", "--quick"], ["train", "--steps", "10"], ["compare"]])
def test_every_command_takes_the_traffic_option(command):
    result = CliRunner().invoke(app, [*command, "--traffic", "wild"])
    assert result.exit_code == 2
    assert "--traffic: highway." in result.output
    assert "drivers: unknown driver population 'wild'" in result.output


def test_a_runs_summary_names_a_population_other_than_highway_envs():
    config = build_config({}, "test", seed=990600, episodes=1, scenario="jam", traffic="cautious")
    config = config.model_copy(update={"highway": config.highway.model_copy(update={"duration": 3})})
    assert run(config, progress=False, snapshot=False).summary["drivers"] == "cautious"
    plain = build_config({}, "test", seed=990600, episodes=1, scenario="jam")
    plain = plain.model_copy(update={"highway": plain.highway.model_copy(update={"duration": 3})})
    assert "drivers" not in run(plain, progress=False, snapshot=False).summary
