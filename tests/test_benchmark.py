"""`drivestack benchmark`: the score orders agents as their paired speed and safety differences
do (full and --quick plans), the command's folder, its refusals."""

import json

import pytest
from typer.testing import CliRunner

from stack.apps.benchmark import BenchmarkPlan
from stack.apps.benchmark_report import episode_score, leaderboard, progress, set_speed_allowance
from stack.apps.cli import app
from stack.results.episode_result import EpisodeResult
from stack.runs.world_allowance import WorldAllowance

SET_SPEED = 30.0
FREE = set_speed_allowance(SET_SPEED)


def episode(number, speed=22.0, at_fault=False, departed=False, changes=1, below_ttc=0.0, jerk=1.0):
    return EpisodeResult(
        episode=number, seed=970_000 + number, steps=600, duration_s=40.0, crashed=at_fault,
        passed_cars=3, lane_changes=changes, mean_speed=speed, peak_lat_accel=1.0, peak_lat_jerk=jerk,
        road_departure=departed, at_fault_collision=at_fault, time_below_ttc_floor_s=below_ttc,
    )  # fmt: skip


def ranking(plan, agents, allowance=FREE):
    """The leaderboard's agent order for `agents` {name: episode(i) -> EpisodeResult} over `plan`,
    every world allowing `allowance`."""
    results = {
        scenario: {
            name: [make(i) for i in range(plan.episodes_of(scenario))] for name, make in agents.items()
        }
        for scenario in plan.scenarios
    }
    allowances = {
        scenario: {970_000 + i: allowance for i in range(plan.episodes_of(scenario))} for scenario in results
    }
    return leaderboard(results, allowances, SET_SPEED)


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
    order = [row["agent"] for row in ranking(plan, agents)]
    assert order[0] == "fast" and order[-1] == "departs"
    faster_and_as_safe = {"fast": lambda i: episode(i, 25.5), "slower": lambda i: episode(i, 25.0)}
    assert [row["agent"] for row in ranking(plan, faster_and_as_safe)] == ["fast", "slower"]


@pytest.mark.parametrize("plan", PLANS, ids=["quick", "full"])
def test_closer_calls_and_dithering_cost_score_at_equal_speed(plan):
    agents = {
        "calm": lambda i: episode(i),
        "close-calls": lambda i: episode(i, below_ttc=8.0),
        "dithers": lambda i: episode(i, changes=12),
    }
    assert ranking(plan, agents)[0]["agent"] == "calm"


def test_an_episode_with_an_at_fault_collision_or_a_departure_scores_zero():
    assert episode_score(episode(0, at_fault=True), FREE).score == 0.0
    assert episode_score(episode(0, departed=True), FREE).score == 0.0
    clean = episode_score(episode(0, speed=SET_SPEED), FREE)
    assert clean.score == pytest.approx(1.0) and clean.progress == 1.0


def test_progress_is_the_share_of_the_headroom_a_world_allows():
    lane_choice = WorldAllowance(allowed=28.0, own_lane=20.0)
    assert progress(20.0, lane_choice) == 0.0 and progress(19.0, lane_choice) == 0.0
    assert progress(24.0, lane_choice) == pytest.approx(0.5) and progress(29.0, lane_choice) == 1.0
    no_choice = WorldAllowance(allowed=20.5, own_lane=20.0)
    assert progress(20.0, no_choice) == pytest.approx(20.0 / 20.5)
    assert progress(22.0, FREE) == pytest.approx(22.0 / SET_SPEED)


def test_the_score_separates_lane_choice_the_set_speed_score_compresses():
    plan = BenchmarkPlan.chosen(quick=True)
    agents = {"chooses": lambda i: episode(i, 24.0), "keeps-lane": lambda i: episode(i, 20.0)}
    rows = ranking(plan, agents, WorldAllowance(allowed=28.0, own_lane=20.0))
    new = [row["overall"]["score"][0] for row in rows]
    old = [row["overall"]["set_speed_score"][0] for row in rows]
    assert [row["agent"] for row in rows] == ["chooses", "keeps-lane"]
    assert new[0] - new[1] == pytest.approx(5 / 13 * 0.5) and old[0] - old[1] == pytest.approx(
        5 / 13 * 4 / 30
    )


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
    header = (out / "benchmark.csv").read_text().splitlines()[0].split(",")
    assert {"allowed_speed", "own_lane_speed", "set_speed_score", "progress"} <= set(header)
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
