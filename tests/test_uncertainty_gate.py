"""The uncertainty gate (`planner.uncertainty`): an ensemble whose members disagree on its chosen
command hands the decision to the fallback, one whose members agree keeps it; `planner.fallback:
none` (or no threshold) leaves the ensemble alone; every episode counts its handed-over decisions,
per world and batched alike, in episodes.csv; recordings show each hand-over; the calibrated
threshold travels in the model file."""

import csv
import math

import numpy as np
import pytest
import torch as th
from torch import nn
from typer.testing import CliRunner

from planner.agents import KeepLaneAgent
from planner.factory import SHIPPED_MODELS
from planner.learned import LearnedAgent, MeanQNetwork, load_agent
from planner.model_file import ModelFileError, load_model, save_model
from planner.model_metadata import ModelMetadata
from planner.uncertainty import (
    DEFAULT_MEASURE,
    GatedAgent,
    advantage_disagreement,
    advantage_ratio,
    coefficient_of_variation,
    compared_as_chosen,
    disagreement,
    dissenting_share,
    gate_measure,
    handed_over,
)
from records import Command, GridConfig
from stack.apps.cli import app
from stack.apps.gate import calibrate, write_threshold
from stack.loop.recording import EpisodeRecording
from stack.runs.episodes import run
from stack.runs.kept import build_agent
from stack.settings.run import build_config

SIZE = 4


class Constant(nn.Module):
    """A member whose Q-values are `values` whatever it sees."""

    def __init__(self, values: list[float]) -> None:
        super().__init__()
        self.values = th.tensor(values, dtype=th.float32)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.values.expand(len(observations), -1)


def ensemble(*members: list[float]) -> LearnedAgent:
    metadata = ModelMetadata(
        kind="mlp", algorithm="ddqn", encoding="observation", observation_size=SIZE, hidden=(8,),
        grid=GridConfig(), members=len(members),
    )  # fmt: skip
    return LearnedAgent(MeanQNetwork([Constant(values) for values in members]), metadata)


def test_disagreement_is_the_members_standard_deviation_of_the_chosen_commands_q_value():
    member_q = np.array([[[1.0, 10.0, 0.0]], [[3.0, 20.0, 0.0]], [[5.0, 30.0, 0.0]]])
    assert disagreement(member_q, np.array([1])) == pytest.approx(np.std([10.0, 20.0, 30.0]))
    assert disagreement(member_q, np.array([0])) == pytest.approx(np.std([1.0, 3.0, 5.0]))
    assert coefficient_of_variation(member_q, np.array([1])) == pytest.approx(np.std([10, 20, 30]) / 20)
    assert disagreement(member_q[:1], np.array([1])) == 0.0
    assert list(handed_over(np.array([0.5, 1.0, 1.5]), 1.0)) == [False, False, True]


def test_the_advantage_measures_read_the_members_margins_of_the_choice_over_the_next_permitted():
    # LEFT (index 0) against STAY: the members differ by 20 on the situation's value but agree
    # LEFT is better by 1 (no doubt about the choice), or agree on LEFT's value and split on it.
    alike = np.array([[[10.0, 9.0, 0.0]], [[20.0, 19.0, 0.0]], [[30.0, 29.0, 0.0]]])
    split = np.array([[[10.0, 9.0, 0.0]], [[10.0, 11.0, 0.0]], [[10.0, 12.0, 0.0]]])
    left, both = np.array([0]), np.array([[1.0, 1.0, 0.0]])
    assert disagreement(alike, left)[0] > disagreement(split, left)[0] == 0.0
    assert advantage_disagreement(alike, left, both)[0] == 0.0
    assert advantage_disagreement(split, left, both)[0] == pytest.approx(np.std([1.0, -1.0, -2.0]))
    assert dissenting_share(alike, left, both)[0] == 0.0
    assert dissenting_share(split, left, both)[0] == pytest.approx(2 / 3)
    assert advantage_ratio(alike, left, both)[0] == 0.0
    assert advantage_ratio(split, left, both)[0] == pytest.approx(np.std([1.0, -1.0, -2.0]) / (2 / 3))
    # RIGHT (index 2) refused: its Q-value of 100 does not count; nothing else permitted: 0.
    refused = np.array([[[10.0, 9.0, 100.0]], [[10.0, 11.0, 100.0]], [[10.0, 12.0, 100.0]]])
    assert advantage_disagreement(refused, left, both)[0] == advantage_disagreement(split, left, both)[0]
    assert advantage_disagreement(refused, left, np.array([[1.0, 0.0, 0.0]]))[0] == 0.0
    assert dissenting_share(refused, left, None)[0] == 1.0


def test_members_that_disagree_hand_the_decision_to_the_fallback():
    learned = ensemble([0.0, 10.0, 0.0], [0.0, 20.0, 0.0], [0.0, 30.0, 0.0])
    gated = GatedAgent(
        learned, KeepLaneAgent(), threshold=1.0, fallback_name="keep-lane", measure="std_q"
    ).gate(np.zeros(SIZE))
    assert gated.actions.tolist() == [Command.STAY] and bool(gated.handed[0])
    assert gated.disagreement[0] == pytest.approx(np.std([10.0, 20.0, 30.0]))


def test_the_default_gate_hands_over_where_the_members_split_on_the_choice_not_on_the_value():
    # The members swing by 20 on every command alike and agree LEFT beats STAY by 1: kept.
    alike = ensemble([10.0, 9.0, 0.0], [20.0, 19.0, 0.0], [30.0, 29.0, 0.0])
    # They agree on LEFT's value and split on STAY's: handed over.
    split = ensemble([10.0, 9.0, 0.0], [10.0, 11.0, 0.0], [10.0, 12.5, 0.0])
    kept = GatedAgent(alike, KeepLaneAgent(), threshold=1.0, fallback_name="keep-lane").gate(np.zeros(SIZE))
    assert kept.actions.tolist() == [Command.LEFT] and not kept.handed.any()
    handed = GatedAgent(split, KeepLaneAgent(), threshold=1.0, fallback_name="keep-lane").gate(np.zeros(SIZE))
    assert handed.actions.tolist() == [Command.STAY] and bool(handed.handed[0])
    assert handed.disagreement[0] == pytest.approx(advantage_ratio(
        np.array([[[10.0, 9.0, 0.0]], [[10.0, 11.0, 0.0]], [[10.0, 12.5, 0.0]]]), np.array([1])
    )[0])  # fmt: skip


def test_the_advantage_is_the_one_the_choice_weighed_with_the_priors_bonus():
    member_q = np.array([[[10.0, 9.0, 0.0]], [[10.0, 11.0, 0.0]], [[10.0, 12.0, 0.0]]])
    rated = member_q.mean(axis=0) + np.array([[3.0, 0.0, 0.0]])  # a bonus for LEFT
    compared = compared_as_chosen(member_q, rated)
    np.testing.assert_allclose(compared, member_q + np.array([3.0, 0.0, 0.0]))
    assert advantage_ratio(compared, np.array([0]))[0] == pytest.approx(np.std([1.0, -1.0, -2.0]) / (7 / 3))
    assert disagreement(compared, np.array([0]))[0] == disagreement(member_q, np.array([0]))[0]


def test_the_gate_weighs_the_choice_against_the_permitted_commands_alone_batched_or_not():
    # The members split on RIGHT, refused by the safety layer: STAY against LEFT is not in doubt.
    metadata = ModelMetadata(
        kind="mlp", algorithm="ddqn", encoding="observation", observation_size=SIZE + 3, hidden=(8,),
        grid=GridConfig(), members=3, action_mask=True,
    )  # fmt: skip
    members = [[1.0, 5.0, 0.0], [1.0, 5.0, 9.0], [1.0, 5.0, 20.0]]
    learned = LearnedAgent(MeanQNetwork([Constant(values) for values in members]), metadata)
    agent = GatedAgent(learned, KeepLaneAgent(), threshold=0.5, fallback_name="keep-lane")
    refused = np.concatenate([np.zeros(SIZE), [1.0, 1.0, 0.0]])
    permitted = np.concatenate([np.zeros(SIZE), [1.0, 1.0, 1.0]])
    kept = agent.gate(refused)
    assert kept.actions.tolist() == [Command.STAY] and kept.disagreement[0] == 0.0 and not kept.handed.any()
    handed = agent.gate(permitted)
    assert handed.actions.tolist() == [Command.RIGHT] and bool(handed.handed[0])
    both = agent.gate(np.stack([refused, permitted]))
    assert both.handed.tolist() == [False, True]
    np.testing.assert_allclose(both.disagreement, [kept.disagreement[0], handed.disagreement[0]])


def test_a_threshold_is_read_by_the_measure_it_was_calibrated_for():
    grid = GridConfig()
    plain = ModelMetadata(kind="mlp", grid=grid)
    assert gate_measure(plain) == DEFAULT_MEASURE == "advantage_ratio"
    assert gate_measure(ModelMetadata(kind="mlp", grid=grid, uncertainty_threshold=3.9)) == "std_q"
    named = ModelMetadata(
        kind="mlp", grid=grid, uncertainty_threshold=2.5, uncertainty_measure="advantage_ratio"
    )
    assert gate_measure(named) == "advantage_ratio"


def test_members_that_agree_keep_the_decision():
    learned = ensemble([5.0, 1.0, 0.0], [5.0, 1.0, 0.0], [5.0, 1.0, 0.0])
    agent = GatedAgent(learned, KeepLaneAgent(), threshold=0.01, fallback_name="keep-lane", measure="std_q")
    gated = agent.gate(np.zeros(SIZE))
    assert gated.actions.tolist() == [Command.LEFT] and not gated.handed.any()
    assert gated.disagreement[0] == 0.0
    batch = np.zeros((3, SIZE))
    assert agent.gate(batch).actions.tolist() == learned.choose(batch).tolist() == [Command.LEFT] * 3


def test_the_gates_choice_is_the_ensembles_to_the_bit():
    agent = load_agent(SHIPPED_MODELS["ddqn"])
    assert isinstance(agent, LearnedAgent)
    rng = np.random.default_rng(1005990)
    batch = rng.uniform(0, 1, (16, agent.observation_size)).astype(np.float32)
    actions, member_q = agent.choose_with_members(batch)
    assert member_q.shape == (3, 16, 3)
    np.testing.assert_array_equal(actions, agent.choose(batch))
    np.testing.assert_array_equal(th.as_tensor(member_q).mean(dim=0).numpy(), agent.q_values(batch))


def short(**overrides):
    return build_config(
        {}, scenario="overtaking",
        **{"planner.agent": "ddqn", "highway.duration": 4, "episodes": 2, "seed": 1005980, **overrides},
    )  # fmt: skip


def test_fallback_none_or_no_threshold_leaves_the_ensemble_alone():
    assert isinstance(build_agent(short(**{"planner.uncertainty_threshold": 1.0}), 0), GatedAgent)
    assert isinstance(
        build_agent(short(**{"planner.uncertainty_threshold": 1.0, "planner.fallback": "none"}), 0),
        LearnedAgent,
    )
    assert SHIPPED_MODELS["ddqn"].exists()
    shipped = load_agent(SHIPPED_MODELS["ddqn"])
    expected = GatedAgent if shipped.metadata.uncertainty_threshold is not None else LearnedAgent
    assert isinstance(build_agent(short(), 0), expected)
    assert isinstance(
        build_agent(short(**{"planner.agent": "dqn", "planner.uncertainty_threshold": 1.0}), 0), LearnedAgent
    )


@pytest.mark.parametrize("fallback", ["mobil", "lookahead"])
def test_each_episode_counts_its_handed_over_decisions_per_world_and_batched_alike(fallback):
    found = {}
    for batched in (True, False):
        everything = short(
            **{"planner.uncertainty_threshold": 0.0, "planner.fallback": fallback, "sim.batched": batched}
        )
        results = run(everything, progress=False, snapshot=False)
        assert results.summary["stepping"] == ("batched" if batched else "per-world")
        found[batched] = [episode.outcome_row() for episode in results.episodes]
        assert all(row["fallback_decisions"] >= 1 for row in found[batched])
        assert results.summary["fallback_decisions"] >= 1
    assert found[True] == found[False]
    never = run(short(**{"planner.uncertainty_threshold": 1e6}), progress=False, snapshot=False)
    plain = run(short(**{"planner.fallback": "none"}), progress=False, snapshot=False)
    assert [e.outcome_row() for e in never.episodes] == [e.outcome_row() for e in plain.episodes]
    assert never.summary["fallback_decisions"] == 0


def test_episodes_csv_counts_the_fallback_decisions(tmp_path):
    out = tmp_path / "run"
    args = ["run", "--agent", "ddqn", "--episodes", "1", "--seed", "1005981", "--scenario", "overtaking"]
    sets = ["highway.duration=3", "planner.uncertainty_threshold=0", "planner.fallback=mobil"]
    result = CliRunner().invoke(app, [*args, *sum((["--set", s] for s in sets), []), "--out", str(out)])
    assert result.exit_code == 0, result.output
    (row,) = csv.DictReader((out / "episodes.csv").open())
    assert int(row["fallback_decisions"]) >= 1


def test_a_recording_shows_a_handed_over_decision(tmp_path):
    recording = EpisodeRecording(tmp_path / "episode.rrd", "ddqn")
    recording.handed_over(4.0, 5.25, 4.1, "lookahead", Command.LEFT)
    ((time, text, level),) = recording.buffers.events
    assert time == 4.0 and level == "WARN"
    assert text == "uncertain: the members disagree by 5.25 > 4.10; lookahead decides LEFT"


def test_the_calibrated_threshold_travels_in_the_model_file(tmp_path):
    arrays, metadata = load_model(SHIPPED_MODELS["ddqn"])
    metadata = {key: value for key, value in metadata.items() if key != "format"}
    save_model(
        tmp_path / "gated.npz",
        arrays,
        {**metadata, "uncertainty_threshold": 3, "uncertainty_calibration": "p98.5"},
    )
    agent = load_agent(tmp_path / "gated.npz")
    assert agent.metadata.uncertainty_threshold == 3.0 and agent.metadata.uncertainty_calibration == "p98.5"
    assert agent.metadata.to_json()["uncertainty_threshold"] == 3.0
    for bad in (-1, math.inf, "3", True):
        save_model(tmp_path / "bad.npz", arrays, {**metadata, "uncertainty_threshold": bad})
        with pytest.raises(
            ModelFileError, match="model metadata uncertainty_threshold: expected a number >= 0"
        ):
            load_agent(tmp_path / "bad.npz")
    save_model(tmp_path / "bad.npz", arrays, {**metadata, "uncertainty_measure": "votes"})
    with pytest.raises(ModelFileError, match="uncertainty_measure: expected one of advantage_ratio, std_q"):
        load_agent(tmp_path / "bad.npz")


def test_a_bad_threshold_or_fallback_is_refused_in_one_line(tmp_path):
    for key, value in (("planner.uncertainty_threshold", "-1"), ("planner.fallback", "rule")):
        result = CliRunner().invoke(
            app, ["run", "--agent", "ddqn", "--set", f"{key}={value}", "--out", str(tmp_path / "x")]
        )
        assert result.exit_code == 2 and key in result.output and "Traceback" not in result.output


def test_calibration_puts_the_threshold_at_the_percentile_of_in_distribution_disagreement(tmp_path):
    found = calibrate(short(), SHIPPED_MODELS["ddqn"], episodes=2, seed=1005982, percentile=90.0)
    assert found.measure == DEFAULT_MEASURE
    (spreads,) = found.disagreements.values()
    assert len(spreads) >= 4 and found.threshold == pytest.approx(np.percentile(spreads, 90.0))
    assert found.shares()["overtaking"] <= 0.2
    written = write_threshold(SHIPPED_MODELS["ddqn"], tmp_path / "gated.npz", found)
    agent = load_agent(written)
    assert agent.metadata.uncertainty_threshold == pytest.approx(found.threshold, abs=1e-6)
    assert agent.metadata.uncertainty_measure == DEFAULT_MEASURE
    assert "90th percentile of advantage_ratio" in str(agent.metadata.uncertainty_calibration)
    assert "seeds 1005982-1005983" in str(agent.metadata.uncertainty_calibration)
    gated = build_agent(short(**{"planner.model": written}), 0)
    assert isinstance(gated, GatedAgent) and gated.threshold == agent.metadata.uncertainty_threshold
    assert gated.measure == DEFAULT_MEASURE


def test_calibrating_a_single_network_is_refused_in_one_line(tmp_path):
    result = CliRunner().invoke(
        app, ["gate-calibrate", "--model", str(SHIPPED_MODELS["dqn"]), "--out", str(tmp_path / "x.npz")]
    )
    assert result.exit_code == 2 and "needs an ensemble" in result.output and "Traceback" not in result.output


def test_an_unknown_measure_is_refused_in_one_line(tmp_path):
    result = CliRunner().invoke(
        app, ["gate-calibrate", "--measure", "votes", "--out", str(tmp_path / "x.npz")]
    )
    assert result.exit_code == 2 and "--measure: expected one of advantage_ratio, std_q" in result.output
    assert "Traceback" not in result.output and not (tmp_path / "x.npz").exists()
