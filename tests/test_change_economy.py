"""The learned agents' economy with lane changes (`planner.learned.economical_choice`): a change is
taken only where the ensemble rates it at least `change_margin` above STAY; the margin comes from the
run config (`planner.change_margin`) or, when that is null, from the model file's metadata, where
its calibration is written; the same law decides per world and in batches; a bad value is refused
in one line."""

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from planner.factory import SHIPPED_MODELS
from planner.learned import LearnedAgent, economical_choice, load_agent
from planner.model_file import ModelFileError, load_model, save_model
from records import Command
from stack.apps.cli import app
from stack.runs.kept import build_agent
from stack.settings.run import build_config
from tests.test_batched_episodes import assert_same_episodes, both_ways

NEAR_TIE = np.array([[10.3, 10.0, 9.0]])
"""LEFT rated 0.3 above STAY, RIGHT 1.0 below."""


def test_a_margin_suppresses_a_change_whose_advantage_is_below_it():
    assert economical_choice(NEAR_TIE, None, 0.0).tolist() == [Command.LEFT]
    assert economical_choice(NEAR_TIE, None, 0.3).tolist() == [Command.LEFT]
    assert economical_choice(NEAR_TIE, None, 0.31).tolist() == [Command.STAY]
    clear = np.array([[0.0, 10.0, 12.0]])
    assert economical_choice(clear, None, 1.9).tolist() == [Command.RIGHT]
    assert economical_choice(clear, None, 2.1).tolist() == [Command.STAY]


def test_a_refused_command_is_never_chosen_and_a_refused_stay_leaves_the_best_change():
    refused_left = np.array([[True, True, True], [False, True, True], [True, False, True]])
    rows = np.repeat(np.array([[10.3, 10.0, 9.0]]), 3, axis=0)
    chosen = economical_choice(rows, refused_left, 0.5)
    assert chosen.tolist() == [Command.STAY, Command.STAY, Command.LEFT]


def test_a_batch_decides_each_row_as_alone():
    rng = np.random.default_rng(1012001)
    rows = rng.normal(0, 1, size=(64, 3))
    permitted = rng.random((64, 3)) > 0.2
    permitted[:, Command.STAY] = True
    batch = economical_choice(rows, permitted, 0.4)
    alone = [economical_choice(rows[i : i + 1], permitted[i : i + 1], 0.4)[0] for i in range(64)]
    assert batch.tolist() == alone


def with_metadata(tmp_path, **fields):
    arrays, metadata = load_model(SHIPPED_MODELS["ddqn"])
    metadata = {key: value for key, value in metadata.items() if key != "format"}
    return save_model(tmp_path / "model.npz", arrays, {**metadata, **fields})


def test_the_calibrated_margin_travels_in_the_model_file_and_the_config_overrides_it(tmp_path):
    path = with_metadata(tmp_path, change_margin=0.7, change_margin_calibration="test")
    agent = load_agent(path)
    assert isinstance(agent, LearnedAgent) and agent.change_margin == 0.7
    assert agent.metadata.to_json()["change_margin_calibration"] == "test"
    run = build_config({"planner": {"agent": "ddqn", "model": str(path)}}, "test")
    assert run.planner.change_margin is None
    built = build_agent(run, 0)
    assert isinstance(built, LearnedAgent) and built.change_margin == 0.7
    mine = build_config({"planner": {"agent": "ddqn", "model": str(path), "change_margin": 0.1}}, "test")
    overridden = build_agent(mine, 0)
    assert isinstance(overridden, LearnedAgent) and overridden.change_margin == 0.1
    plain = with_metadata(tmp_path, change_margin=None, change_margin_calibration=None)
    assert load_agent(plain).change_margin == 0.0


@pytest.mark.parametrize("bad", [-0.1, 10.5, math.inf, "0.3", True])
def test_a_bad_margin_in_a_model_file_is_refused_in_one_line(tmp_path, bad):
    path = with_metadata(tmp_path, change_margin=bad)
    with pytest.raises(ModelFileError, match=r"model metadata change_margin: expected a number in \[0, 10\]"):
        load_agent(path)


@pytest.mark.parametrize("value", ["-1", "11", "many"])
def test_a_bad_margin_in_the_run_config_exits_2_in_one_line(tmp_path, value):
    result = CliRunner().invoke(
        app,
        ["run", "--agent", "ddqn", "--set", f"planner.change_margin={value}", "--out", str(tmp_path / "x")],
    )
    assert result.exit_code == 2, result.output
    assert "planner.change_margin" in result.output and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_batched_episodes_with_a_margin_are_the_episodes_run_alone():
    batched, alone = both_ways(3, scenario="overtaking", planner__agent="ddqn", planner__change_margin=0.5)
    assert_same_episodes(batched, alone)
    assert any(e.lane_changes for e in batched)
