"""`drivestack benchmark`: the score orders agents as their paired speed and safety differences
do (full and --quick plans), the command's folder, its refusals."""

import json

import pytest
from typer.testing import CliRunner

from stack.apps.benchmark import BenchmarkPlan
from stack.apps.benchmark_report import episode_score, leaderboard
from stack.apps.cli import app
from stack.results.episode_result import EpisodeResult

SET_SPEED = 30.0


def episode(number, speed=22.0, at_fault=False, departed=False, changes=1, below_ttc=0.0, jerk=1.0):
    return EpisodeResult(
        episode=number, seed=970_000 + number, steps=600, duration_s=40.0, crashed=at_fault,
        passed_cars=3, lane_changes=changes, mean_speed=speed, peak_lat_accel=1.0, peak_lat_jerk=jerk,
        road_departure=departed, at_fault_collision=at_fault, time_below_ttc_floor_s=below_ttc,
    )  # fmt: skip


def ranking(plan, agents):
    """The leaderboard's agent order for `agents` {name: episode(i) -> EpisodeResult} over `plan`."""
    results = {
        scenario: {
            name: [make(i) for i in range(plan.episodes_of(scenario))] for name, make in agents.items()
        }
        for scenario in plan.scenarios
    }
    return [row["agent"] for row in leaderboard(results, SET_SPEED)]


PLANS = [BenchmarkPlan.chosen(quick=True), BenchmarkPlan.chosen(quick=False)]


@pytest.mark.parametrize("plan", PLANS, ids=["quick", "full"])
def test_the_score_orders_agents_by_safety_then_speed(plan):
    spread = lambda i: 0.5 * (i % 3)  # noqa: E731 - the same spread of speeds for every agent
    agents = {
        "crashes-once": lambda i: episode(i, 25.0 + spread(i), at_fault=i == 1),
        "fast": lambda i: episode(i, 25.0 + spread(i)),
        "slow": lambda i: episode(i, 20.0 + spread(i)),
        "departs": lambda i: episode(i, 26.0 + spread(i), departed=i % 2 == 0),
    }
    order = ranking(plan, agents)
    assert order[0] == "fast" and order[-1] == "departs"
    faster_and_as_safe = {"fast": lambda i: episode(i, 25.5), "slower": lambda i: episode(i, 25.0)}
    assert ranking(plan, faster_and_as_safe) == ["fast", "slower"]


@pytest.mark.parametrize("plan", PLANS, ids=["quick", "full"])
def test_closer_calls_and_dithering_cost_score_at_equal_speed(plan):
    agents = {
        "calm": lambda i: episode(i),
        "close-calls": lambda i: episode(i, below_ttc=8.0),
        "dithers": lambda i: episode(i, changes=12),
    }
    assert ranking(plan, agents)[0] == "calm"


def test_an_episode_with_an_at_fault_collision_or_a_departure_scores_zero():
    assert episode_score(episode(0, at_fault=True), SET_SPEED).score == 0.0
    assert episode_score(episode(0, departed=True), SET_SPEED).score == 0.0
    clean = episode_score(episode(0, speed=SET_SPEED), SET_SPEED)
    assert clean.score == pytest.approx(1.0) and clean.progress == 1.0


def test_the_plans_use_report_seeds_and_their_episode_counts():
    quick, full = PLANS
    assert full.episodes_of("jam") == 500 and full.episodes_of("random") == 300
    assert quick.episodes_of("random") == quick.episodes == 4
    assert full.seed == quick.seed == 970_000 and "random" in full.scenarios and len(full.scenarios) >= 10


def test_benchmark_writes_its_folder_and_refuses_bad_input(tmp_path):
    out = tmp_path / "bench"
    arguments = ["benchmark", "--agents", "keep-lane,lookahead", "--episodes", "1", "--duration", "2"]
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    for name in ("summary.json", "config.yaml", "benchmark.csv", "leaderboard.png"):
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    assert {row["agent"] for row in summary["leaderboard"]} == {"keep-lane", "lookahead"}
    assert not summary["interrupted"] and len(summary["leaderboard"][0]["scenarios"]) == len(
        PLANS[0].scenarios
    )
    again = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume"])
    assert again.exit_code == 2 and "nothing to resume" in again.output
    no = ["--out", str(tmp_path / "no")]
    for bad in (
        ["--agents", "", *no],
        ["--agents", "mobil,,rule", *no],
        ["--agents", "mobil,mobil", *no],
        ["--agents", "genius", *no],
        ["--resume"],
    ):
        refused = CliRunner().invoke(app, ["benchmark", *bad])
        assert refused.exit_code == 2 and len(refused.output.strip().splitlines()) == 1, (bad, refused.output)
