"""`drivestack run` and `compare` on batched worlds (`stack.runs.batch_episodes`): each episode's
result, every outcome field and the per-tick trace, is the one the per-world loop reports (passed
cars, comfort, TTC, R157, standstill, collision class, counts), for the agents that decide on the
grid (learned, MOBIL, rule, keep-lane, random, the lookahead), through sensors, on roads of several
lane counts; the configs a batch does not run are refused in one line and run one world at a time."""

from __future__ import annotations

import numpy as np
import pytest

from stack.fault.truth_ring import TruthRing
from stack.results.episode_result import EpisodeResult
from stack.runs.batch_episodes import BATCH_WORLDS, batch_refusal, batches, run_batched
from stack.runs.episodes import run, run_episode
from stack.settings.run import build_config
from stack.sim.batch.traffic import TrafficBatch
from stack.worlds.scenarios import names as scenario_names
from tests.helpers import straight_lanes


def assert_same_episodes(batched: list[EpisodeResult], alone: list[EpisodeResult]) -> None:
    assert [e.episode for e in batched] == [e.episode for e in alone]
    for mine, theirs in zip(batched, alone, strict=True):
        assert mine.outcome_row() == theirs.outcome_row(), mine.episode
        assert mine.trace == theirs.trace, mine.episode
        by_cause = [
            value for name, value in mine.outcome_row().items() if name.startswith("emergency_brakings_")
        ]
        assert len(by_cause) == 5 and sum(by_cause) == mine.emergency_brakings, mine.episode


def both_ways(episodes: int, **overrides: object) -> tuple[list[EpisodeResult], list[EpisodeResult]]:
    """`episodes` episodes of a config run as one batch and one world at a time."""
    config = build_config({}, "test", seed=625000, episodes=episodes, **overrides)
    assert batch_refusal(config) is None
    return run_batched(config, list(range(episodes))), [run_episode(config, e) for e in range(episodes)]


@pytest.mark.parametrize(
    ("scenario", "agent"),
    [
        ("overtaking", "ddqn"),
        ("noisy", "mobil"),
        ("random", "ddqn"),
        ("incident", "rule"),
        ("overtaking", "lookahead"),
        ("random", "lookahead"),
        ("random", "rule"),
        ("random", "mobil"),
        ("exit", "random"),
    ],
)
def test_each_episode_of_a_batch_is_the_episode_run_alone(scenario: str, agent: str) -> None:
    batched, alone = both_ways(3, scenario=scenario, planner__agent=agent)
    assert_same_episodes(batched, alone)
    assert sum(e.passed_cars for e in batched) > 0
    assert any(e.lane_changes for e in batched) or agent == "rule"


def test_collisions_are_classified_as_one_world_classifies_them() -> None:
    """Random commands in dense traffic, no safety layer, late emergency braking: the ego collides,
    at fault (its own lane change)."""
    batched, alone = both_ways(
        8,
        scenario="dense",
        planner__agent="random",
        planner__safety__enabled=False,
        controller__emergency_ttc_s=0.01,
    )
    assert_same_episodes(batched, alone)
    kinds = [e.collision_kind for e in batched if e.crashed]
    assert kinds and all(kind for kind in kinds)
    assert sum(e.at_fault_collision for e in batched) == sum(e.at_fault_collision for e in alone) > 0


def test_a_batch_judges_each_collision_s_fault_from_its_own_truth_as_one_world_does(monkeypatch) -> None:
    """Blind drivers cut in on MOBIL (episodes of seed 0 that collide): the batch replays R157's
    reference driver over the truth it kept (`stack.fault.truth_ring`), never running an episode
    again, and judges as the episode run alone does."""
    config = build_config({}, "test", scenario="highway-v0", traffic="blind", planner__agent="mobil", seed=0)
    alone = [run_episode(config, episode) for episode in (6, 33)]

    def run_again(*_: object) -> None:
        raise AssertionError("the batch ran an episode again to judge it")

    monkeypatch.setattr("stack.runs.batch_episodes.run_episode", run_again)
    batched = run_batched(config, [6, 33])
    assert all(e.crashed and e.fault_reason for e in batched)
    assert_same_episodes(batched, alone)


def test_the_truth_ring_says_nothing_of_a_world_it_did_not_see_on_every_tick() -> None:
    """A world left out of a tick has no history here (its fault is judged by running it again);
    the others' hold every tick since their reset, the reset frame first, at most 5 s and a frame."""
    batch = TrafficBatch(build_config({}, "test", scenario="highway-v0").highway, 2)
    batch.reset([0, 1])
    ring = TruthRing(2, batch.dt)
    ring.reset([0, 1], batch.arrays.world_batch(), batch.arrays, batch.time)
    for tick in range(80):
        stepped = np.array([True, tick != 70])
        batch.step(np.zeros(2), np.zeros(2), stepped)
        ring.record(stepped, batch.arrays.world_batch(), batch.arrays, batch.time)
    lanes = straight_lanes(4)
    assert ring.history(1, lanes) is None
    history = ring.history(0, lanes)
    assert history is not None and len(history) == round(5.0 / batch.dt) + 1
    assert history[-1].time == pytest.approx(float(batch.time[0]))
    ring.reset([1], batch.arrays.world_batch(), batch.arrays, batch.time)
    (restarted,) = ring.history(1, lanes) or ()
    assert restarted.time == pytest.approx(float(batch.time[1])) and restarted.ids[0] == batch.arrays.ego[1]


def test_a_run_is_the_same_in_batches_and_over_processes() -> None:
    config = build_config(
        {}, "test", scenario="jam", planner__agent="mobil", seed=625100, episodes=5, highway__duration=15
    )
    one = run(config, progress=False, snapshot=False)
    two = run(config, progress=False, jobs=2, snapshot=False)
    assert [e.outcome_row() for e in one.episodes] == [e.outcome_row() for e in two.episodes]
    assert one.summary["episodes"] == 5 and all(e.snapshot is None for e in one.episodes)
    first = run(config, progress=False)
    assert first.episodes[0].snapshot is not None
    assert [e.outcome_row() for e in first.episodes] == [e.outcome_row() for e in one.episodes]
    assert one.summary["stepping"] == "batched" and "stepping_reason" not in one.summary
    alone = run(config.model_copy(update={"episodes": 2}), progress=False, snapshot=False, jobs=1)
    assert alone.summary["stepping"] == "batched"


def test_a_run_stepped_one_world_at_a_time_says_why_in_its_summary() -> None:
    config = build_config({}, "test", scenario="jam", seed=625100, episodes=1, sim__batched=False)
    summary = run(config, progress=False, snapshot=False).summary
    assert summary["stepping"] == "per-world" and summary["stepping_reason"] == "sim.batched is off"


@pytest.mark.parametrize(
    ("overrides", "reason"),
    [
        ({"planner__agent": "oracle"}, "plans on copies"),
        ({"planner__agent": "tabular"}, "not 'tabular'"),
        ({"controller__type": "mpc"}, "PID tracker"),
        ({"sim__backend": "fast"}, "vector backend"),
        ({"sim__plant": "dynamic"}, "kinematic plant"),
    ],
)
def test_what_a_batch_does_not_run_is_refused_in_one_line(overrides: dict, reason: str) -> None:
    refused = batch_refusal(build_config({}, "test", **overrides))
    assert refused is not None and reason in refused and "\n" not in refused


def test_batches_are_even_and_at_most_the_batch_size() -> None:
    assert batches([], 2) == []
    assert [len(b) for b in batches(list(range(200)), 2)] == [50, 50, 50, 50]
    assert [len(b) for b in batches(list(range(5)), 2)] == [3, 2]
    split = batches(list(range(300)), 1)
    assert max(map(len, split)) <= BATCH_WORLDS and sum(split, []) == list(range(300))


@pytest.mark.slow
@pytest.mark.parametrize("scenario", scenario_names())
def test_every_scenario_and_default_agent_in_batches_is_the_same_run(scenario: str) -> None:
    for agent in ("ddqn", "rule", "mobil", "keep-lane"):
        overrides = {"scenario": scenario, "planner__agent": agent}
        if batch_refusal(build_config({}, "test", **overrides)) is None:
            assert_same_episodes(*both_ways(6, **overrides))


def test_a_stopped_batch_keeps_each_episode_that_ended_before_the_stop() -> None:
    """Crashes end some worlds' episodes early: each is handed on as it ends, so a Ctrl-C (here
    raised where the journal records them) keeps them though their batch never finished."""
    config = build_config(
        {},
        "test",
        scenario="incident",
        planner__agent="random",
        planner__safety__enabled=False,
        controller__emergency_ttc_s=0.01,
        seed=625000,
        episodes=8,
    )
    handed: list[int] = []

    def stop_after_two(result: EpisodeResult) -> None:
        handed.append(result.episode)
        if len(handed) == 2:
            raise KeyboardInterrupt

    stopped = run(config, progress=False, on_finished=stop_after_two, snapshot=False)
    assert stopped.summary["interrupted"] and [e.episode for e in stopped.episodes] == sorted(handed)
    assert len(stopped.episodes) == 2 < config.episodes


def test_batching_is_not_part_of_a_folder_s_fingerprint() -> None:
    """`--resume` goes on with a folder whether or not its episodes ran batched (the same results),
    and with folders written before `sim.batched` existed (the fingerprint leaves it out)."""
    from stack.apps.resume import run_owner
    from stack.apps.training import training_owner
    from stack.settings.history import HOW_NOT_WHAT
    from stack.settings.run import config_text

    batched = build_config({}, "test", scenario="jam")
    alone = build_config({}, "test", scenario="jam", sim__batched=False)
    assert run_owner([batched], "run") == run_owner([alone], "run")
    assert training_owner(batched) == training_owner(alone)
    assert "batched" in config_text(alone) and "batched" not in config_text(batched, exclude=HOW_NOT_WHAT)
    assert batch_refusal(alone) == "sim.batched is off"


def test_a_batch_reports_each_world_s_share_of_the_control_step() -> None:
    config = build_config({}, "test", scenario="jam", planner__agent="mobil", seed=625200, episodes=2)
    for result in run_batched(config, [0, 1]):
        assert 0.0 < result.solve_ms_p50 <= result.solve_ms_p95 < 1e3
