"""An ensemble model file (`drivestack ensemble`): Q-networks trained apart, bundled into one file
that decides on the mean of their Q-values; checked member by member on load, refused in one line
when its members do not share one observation and one network, and never a training start or an
SB3 export (it has no single network)."""

import csv
import errno
from unittest import mock

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from planner.factory import SHIPPED_MODELS
from planner.learned import MeanQNetwork, export_q_network, load_agent, save_ensemble
from planner.model_file import ModelFileError, load_model, save_model
from stack.apps.cli import app
from tests.test_lane_network import LANES, METADATA, SIZE, lane_dqn


@pytest.fixture(scope="module")
def members(tmp_path_factory):
    """Two lane networks of one shape with different weights (trained for 64 and 32 steps)."""
    folder = tmp_path_factory.mktemp("members")
    return [export_q_network(lane_dqn(steps), folder / f"member{steps}.npz", METADATA) for steps in (64, 32)]


def test_an_ensemble_decides_on_the_mean_of_its_members_q_values(members, tmp_path):
    path = save_ensemble(members, tmp_path / "ensemble.npz")
    agent = load_agent(path)
    assert isinstance(agent.network, MeanQNetwork) and agent.metadata.members == 2
    assert agent.sees_permitted and agent.metadata.kind == "lane-mlp"
    batch = np.random.default_rng(5).uniform(-1, 1, (32, SIZE)).astype(np.float32)
    first, second = (load_agent(member).q_values(batch) for member in members)
    assert not np.allclose(first, second), "the members differ"
    np.testing.assert_allclose(agent.q_values(batch), (first + second) / 2, rtol=1e-6, atol=1e-6)
    assert load_model(path)[1]["members"] == 2 and "members" not in load_model(members[0])[1]


def test_an_ensemble_file_is_checked_member_by_member(members, tmp_path):
    arrays, metadata = load_model(save_ensemble(members, tmp_path / "ensemble.npz"))
    cut = {**arrays, "member1.head.0.weight": arrays["member1.head.0.weight"][:, :-1]}
    save_model(tmp_path / "cut.npz", cut, metadata)
    with pytest.raises(ModelFileError, match="model arrays do not match its metadata"):
        load_agent(tmp_path / "cut.npz")
    save_model(tmp_path / "three.npz", arrays, {**metadata, "members": 3})
    with pytest.raises(ModelFileError, match="model arrays do not match its metadata"):
        load_agent(tmp_path / "three.npz")
    for members_value in (0, 17, "2", True, 2.0):
        save_model(tmp_path / "bad.npz", arrays, {**metadata, "members": members_value})
        with pytest.raises(ModelFileError, match=r"model metadata members: expected an integer in 1\.\.16"):
            load_agent(tmp_path / "bad.npz")
    table = {"q_table": np.zeros((4, 3))}
    save_model(tmp_path / "table.npz", table, {"kind": "qtable", "grid": metadata["grid"], "members": 2})
    with pytest.raises(ModelFileError, match=r"members: expected an integer in 1\.\.1$"):
        load_agent(tmp_path / "table.npz")


def test_members_that_do_not_share_one_observation_are_refused_in_one_line(members, tmp_path):
    arrays, metadata = load_model(members[1])
    save_model(tmp_path / "unmasked.npz", arrays, {**metadata, "action_mask": False})
    out = tmp_path / "ensemble.npz"
    runner = CliRunner()
    for models, expected in (
        ([members[0], tmp_path / "unmasked.npz"], "unmasked.npz: action_mask False differs from"),
        ([members[0]], "an ensemble takes 2 to 16 model files, not 1"),
        ([members[0], tmp_path / "missing.npz"], "missing.npz: no such model file"),
    ):
        result = runner.invoke(app, ["ensemble", *map(str, models), "--out", str(out)])
        assert result.exit_code == 2 and expected in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1 and not out.exists()
    assert runner.invoke(app, ["ensemble", *map(str, members), "--out", str(out)]).exit_code == 0
    again = runner.invoke(app, ["ensemble", str(out), str(members[0]), "--out", str(tmp_path / "again.npz")])
    assert again.exit_code == 2 and "already an ensemble of 2; give its members" in again.output
    exists = runner.invoke(app, ["ensemble", *map(str, members), "--out", str(out)])
    assert exists.exit_code == 2 and f"--out: {out} exists" in exists.output
    full = tmp_path / "full.npz"
    with mock.patch("numpy.savez", side_effect=OSError(errno.ENOSPC, "No space left on device")):
        disk = runner.invoke(app, ["ensemble", *map(str, members), "--out", str(full)])
    assert disk.exit_code == 2 and "--out: cannot write" in disk.output and "No space left" in disk.output
    assert len(disk.output.strip().splitlines()) == 1 and list(tmp_path.glob("full.npz*")) == []


def test_an_ensemble_of_one_network_twice_drives_as_that_network(tmp_path):
    shipped = SHIPPED_MODELS["dqn"]
    twice = tmp_path / "twice.npz"
    runner = CliRunner()
    assert runner.invoke(app, ["ensemble", str(shipped), str(shipped), "--out", str(twice)]).exit_code == 0
    rows = {}
    options = ["--agent", "dqn", "--scenario", "overtaking", "--episodes", "1", "--seed", "3"]
    for name, model in (("one", shipped), ("twice", twice)):
        result = runner.invoke(app, ["run", *options, "--model", str(model), "--out", str(tmp_path / name)])
        assert result.exit_code == 0, result.output
        with open(tmp_path / name / "episodes.csv") as episodes:
            rows[name] = list(csv.DictReader(episodes))
    assert rows["one"] == rows["twice"]


def test_an_ensemble_neither_starts_a_training_run_nor_exports_to_sb3(members, tmp_path):
    path = save_ensemble(members, tmp_path / "ensemble.npz")
    config = tmp_path / "lanes.yaml"
    config.write_text(yaml.safe_dump({**LANES, "train": {**LANES["train"], "init_model": str(path)}}))
    runner = CliRunner()
    train = runner.invoke(app, ["train", "-c", str(config), "--out", str(tmp_path / "run")])
    assert train.exit_code == 2 and "is an ensemble of 2; start from one member" in train.output, train.output
    export = runner.invoke(app, ["export", str(path), "--sb3", str(tmp_path / "model.zip")])
    assert export.exit_code == 2 and "has no SB3 counterpart; export a member" in export.output
    assert not (tmp_path / "run").exists() and not (tmp_path / "model.zip").exists()
