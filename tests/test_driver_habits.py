"""The drivers' habits (`stack.sim.vector.habits`): distracted drivers act on a delayed view and brake
without cause at their stated rate, blind drivers' MOBIL does not see the ego, cautious drivers
ease off for the ego's lane change into their lane; `mixed` holds them all and `random` draws a
population per episode. Each is the same per seed on the vector road and in the batch, and the
`stock` and `fast` backends refuse them in one line."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.runs.batch_episodes import batch_refusal, run_batched
from stack.runs.episodes import run_episode
from stack.settings.run import ConfigError, build_config
from stack.sim.drivers import SEEN_FRAMES, habits_of
from stack.sim.envs import VECTOR_HIGHWAY
from stack.sim.highway import env_config
from stack.sim.vector import idm_drivers
from stack.sim.vector.habits import (
    SeenPast,
    delayed_accelerations,
    seen_acceleration,
    sudden_accelerations,
    unseen_ego,
    yielders,
    yielding,
)
from stack.worlds.drivers import MIXED_SHARES, POPULATION_RANGES, RANDOM_CHOICES, stock_drives
from tests.test_batched_episodes import assert_same_episodes
from tests.test_sim_batched import assert_worlds_identical

HABIT_POPULATIONS = ["distracted", "blind", "cautious", "mixed"]


def highway_in(scenario: str, drivers: object):
    return build_config({}, scenario=scenario, traffic=drivers).highway


def spawned(scenario: str, drivers: object, seed: int):
    env = gym.make(VECTOR_HIGHWAY, config=env_config(highway_in(scenario, drivers)), disable_env_checker=True)
    env.reset(seed=seed)
    return env


def test_sudden_brakings_come_at_the_stated_rate_and_strength():
    """One driver at 1 braking a minute for 1 s, 3-6 m/s^2: over 10 simulated hours at 15 Hz,
    onsets at the rate (Poisson, 600 expected) and braking 1/60 of the time."""
    frames = 15 * 3600 * 10
    chance = -np.expm1(-1 / 60 / 15)
    acceleration = np.zeros(frames)
    sudden_accelerations(
        acceleration,
        np.zeros(frames, dtype=np.int64),
        np.arange(frames),
        np.array([1002001]),
        np.array([chance]),
        np.array([15]),
        np.array([4.5]),
    )
    braking = acceleration < 0
    onsets = int((braking[1:] & ~braking[:-1]).sum())
    assert 500 < onsets < 700
    assert set(np.unique(acceleration).tolist()) == {-4.5, 0.0}
    assert braking.mean() == pytest.approx(1 / 60, rel=0.15)


def test_the_distracted_drivers_draws_are_the_issues():
    ranges = POPULATION_RANGES["distracted"]
    assert ranges.perception_delay_s == (0.5, 1.5)
    assert ranges.sudden_braking_mps2 == (3.0, 6.0)
    env = spawned("dense", "distracted", seed=1002002)
    habits = [habits_of(v) for v in env.unwrapped.road.vehicles[1:]]
    delays = [h.delay_frames for h in habits]
    assert min(delays) >= 7 and max(delays) <= 23 < SEEN_FRAMES and len(set(delays)) > 5
    assert all(3.0 <= h.sudden_braking_mps2 <= 6.0 for h in habits)
    assert len({h.key for h in habits}) == len(habits)
    env.close()


def test_a_delayed_driver_acts_on_the_gap_it_saw():
    """A leader 30 m ahead closing in 1 m a frame: with a delay of 10 frames the driver brakes as
    for the gap of 10 frames ago (40 m), not today's."""
    seen = SeenPast(1, 2)
    for frame in range(20):
        seen.push(np.zeros(1, dtype=int), np.array([[0.0, 50.0 - frame]]), np.array([[20.0, 20.0]]))
    free, laws = 0.5, (3.0, 10.0, 1.5, 2 * np.sqrt(15.0))
    now, then = (seen_acceleration(free, 20.0, *laws, gap, 0.0) for gap in (31.0, 41.0))
    acceleration = np.zeros(1)
    delayed_accelerations(
        acceleration, np.zeros(1, dtype=np.int64), np.array([0]), np.array([1]), 2, np.array([10]),
        seen.s, seen.speed, seen.pushed, np.array([free]), np.array([20.0]),
        *(np.array([value]) for value in laws),
    )  # fmt: skip
    assert acceleration[0] == then and then > now


def test_a_blind_driver_does_not_see_the_ego_as_its_new_follower():
    rears = np.array([0, 3, 0, -1])
    blind = np.array([True, True, False, True])
    np.testing.assert_array_equal(unseen_ego(rears, blind, 0), [-1, 3, 0, -1])


def test_a_yielding_driver_eases_off_behind_the_egos_lane_change_no_harder_than_comfortable():
    yields = np.array([True, True, True, False])
    lane, s = np.array([1, 1, 2, 1]), np.array([10.0, 60.0, 10.0, 10.0])
    np.testing.assert_array_equal(yielders(yields, lane, 1, s, 50.0), [True, False, False, False])
    assert not yielders(yields, lane, -1, s, 50.0).any()
    eased = yielding(np.array([1.0, 1.0]), np.array([-0.5, -4.0]), np.array([-1.2, -1.2]))
    np.testing.assert_array_equal(eased, [-0.5, -1.2])


def test_mixed_holds_every_population_and_random_draws_one_per_episode():
    assert set(MIXED_SHARES) == set(RANDOM_CHOICES) - {"mixed"}
    assert sum(MIXED_SHARES.values()) == pytest.approx(1.0)
    drawn = {spawned("dense", "random", seed).unwrapped.drivers_drawn for seed in range(1002010, 1002030)}
    assert len(drawn) >= 4 and drawn <= set(RANDOM_CHOICES)
    again = spawned("dense", "random", 1002010).unwrapped
    assert again.drivers_drawn == spawned("dense", "random", 1002010).unwrapped.drivers_drawn


@pytest.mark.parametrize("population", HABIT_POPULATIONS)
def test_each_batched_world_is_the_vector_world_with_habits(population):
    assert_worlds_identical(highway_in("dense", population), [1002040, 1002041], frames=150)


def test_a_batched_run_is_the_per_world_run_with_yielding_and_blind_drivers(monkeypatch):
    """MOBIL's ego changes lane in front of cautious (yielding) and blind drivers: the batched
    run shows the traffic the ego's intent lane as the per-world loop does, and drivers ease off."""
    eased: list[int] = []

    def counted(acceleration, behind_ego, comfort_acc_min):
        out = yielding(acceleration, behind_ego, comfort_acc_min)
        eased.append(int((out < acceleration).sum()))
        return out

    monkeypatch.setattr(idm_drivers, "yielding", counted)
    config = build_config(
        {},
        "test",
        seed=1002050,
        episodes=3,
        scenario="overtaking",
        traffic={"cautious": 0.5, "blind": 0.25, "distracted": 0.25},
        planner__agent="mobil",
    )
    assert batch_refusal(config) is None
    batched = run_batched(config, [0, 1, 2])
    assert_same_episodes(batched, [run_episode(config, e) for e in range(3)])
    assert any(e.lane_changes for e in batched)
    assert sum(eased) > 0, "a yielding driver eased off behind the ego's lane change"


def test_the_stock_and_fast_backends_refuse_drivers_with_habits_in_one_line():
    assert stock_drives("calibrated") and stock_drives(None) and not stock_drives("mixed")
    for population in ("distracted", "blind", "cautious", "mixed", "random"):
        with pytest.raises(ConfigError, match="sim.backend: the stock backend drives"):
            build_config({"sim": {"backend": "stock"}}, scenario="dense", traffic=population)
    result = CliRunner().invoke(
        app,
        ["run", "--scenario", "dense", "--traffic", "blind", "--set", "sim.backend=fast", "--episodes", "1"],
    )
    assert result.exit_code == 2
    assert "use the vector backend" in result.output and "Traceback" not in result.output


def test_the_benchmark_scores_every_agent_under_each_population(tmp_path):
    out = tmp_path / "axis"
    result = CliRunner().invoke(
        app,
        [
            "benchmark", "--agents", "keep-lane", "--traffic", "highway-env,blind", "--episodes", "1",
            "--duration", "1", "--seed", "1002060", "--out", str(out), "--jobs", "1", "--no-progress",
        ],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "traffic drivers: blind" in result.output
    assert "| keep-lane | " in result.output.split("agents x traffic drivers")[1]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["populations"] == ["highway-env", "blind"]
    assert set(summary["scores"]["keep-lane"]) == {"highway-env", "blind"}
    assert json.loads((out / "blind" / "summary.json").read_text())["drivers"] == "blind"
    repeated = CliRunner().invoke(
        app, ["benchmark", "--traffic", "blind,blind", "--out", str(tmp_path / "b")]
    )
    assert repeated.exit_code == 2 and "each population once" in repeated.output
