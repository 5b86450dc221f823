"""`drivestack sweep` checked like the other commands (issue 36): a bad sweep file, a trial that
could never run and a folder it may not write are one line (exit 2) before Ray starts and before
anything is written."""

import json
from types import SimpleNamespace

import pytest
import yaml

from stack.apps import commands, training
from stack.runtime.owner import MARKER, Owner, claim
from tests.test_cli import tiny_config_file
from tests.test_hostile_inputs import one_line_refusal
from tests.test_train import TINY


@pytest.fixture
def no_ray(monkeypatch):
    """Every refusal here comes before Ray would start."""
    monkeypatch.setattr(commands, "ray_or_fail", lambda *_: pytest.fail("Ray was started"))


def sweep_file(tmp_path, **fields) -> str:
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(TINY))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"config": "base.yaml", **fields}))
    return str(path)


@pytest.mark.parametrize(
    ("fields", "expected"),
    [
        ({"space": {"seed": [1]}, "samples": True}, "samples: expected a number, got a boolean (true)"),
        ({"space": {"seed": [1]}, "concurrent": True}, "concurrent: expected a number, got a boolean"),
        ({"space": {"train.gamma": [0.9, True]}}, "space: train.gamma: expected a number, got a boolean"),
        ({"space": {"seed": [1]}, "fixed": {"train.steps": "yes"}}, "fixed: train.steps: Input should be"),
        (
            {"space": {"train.batch_size": {"uniform": [8, 64]}}},
            "space: train.batch_size: an integer; draw it with randint or list its values",
        ),
        ({"space": {"seed": list(range(1001))}}, "space: seed: at most 1000 values, got 1001"),
        (
            {"space": {"seed": list(range(200)), "train.gamma": [0.9] * 100}},
            "space: 20000 trials; a sweep holds at most 10000",
        ),
        ({"space": {"train.buffer_size": [100, 40_000_000]}}, "train.buffer_size: 40000000 transitions need"),
    ],
)
def test_a_bad_sweep_is_one_line_before_ray_starts(tmp_path, no_ray, monkeypatch, fields, expected):
    monkeypatch.setattr(training, "available_memory_bytes", lambda: 2**30)
    out = tmp_path / "out"
    one_line_refusal(["sweep", "--config", sweep_file(tmp_path, **fields), "--out", str(out)], expected)
    assert not out.exists()


def test_trials_that_need_more_cpus_than_there_are_are_refused_before_ray_starts(
    tmp_path, no_ray, monkeypatch
):
    from stack.runtime import machine

    monkeypatch.setattr(machine, "usable_cpus", lambda: 2)
    spec = sweep_file(tmp_path, space={"train.envs": [1, 3]})
    one_line_refusal(
        ["sweep", "--config", spec, "--out", str(tmp_path / "out")],
        "train.envs: a trial steps 3 environments, one CPU each, but this machine has 2 CPUs",
    )


def test_a_folder_the_sweep_may_not_write_is_refused_before_ray_starts(tmp_path, no_ray):
    spec = sweep_file(tmp_path, space={"seed": [1]})
    taken = tmp_path / "taken"
    claim(taken, Owner("run", "x"), resuming=False).close()
    (taken / "summary.json").write_text("{}")
    one_line_refusal(["sweep", "--config", spec, "--out", str(taken)], "already holds the results of `run`")
    (sweep := tmp_path / "sweep").mkdir()
    (sweep / "sweep.yaml").write_text(yaml.safe_dump({"config": "config.yaml", "space": {"seed": [1]}}))
    (sweep / "config.yaml").write_text(yaml.safe_dump(TINY))
    one_line_refusal(
        ["sweep", "--resume", str(sweep), "--out", str(taken)], "--out: has no effect with --resume"
    )
    (sweep / MARKER).write_text(json.dumps({"command": "compare", "config": "y"}))
    one_line_refusal(["sweep", "--resume", str(sweep)], "holds the results of `compare`, not of `sweep`")


def test_a_sweep_trial_folder_is_not_resumed_as_a_training_run(tmp_path):
    trial = tmp_path / "trials" / "abc_00000"
    claim(trial, Owner("sweep trial", "p"), resuming=True).close()
    (trial / "config.yaml").write_text(tiny_config_file(tmp_path).read_text())
    one_line_refusal(
        ["train", "--resume", str(trial)], "holds the results of `sweep trial`, not a training run"
    )


class Grid(list):
    """A stand-in for Tune's ResultGrid: its results, and Tune's records of the trials beside them."""


def test_a_trial_stopped_before_it_reported_keeps_its_parameters_and_id():
    """A sweep stopped while a trial had not yet reported: Tune's Result of it has no parameters and
    no metrics (the report read `None.get`); they come from Tune's record of the trial."""
    from stack.apps.sweep import tune_trials

    reported = SimpleNamespace(metrics={"trial_id": "t_00000", "step": 40, "finished": True}, error=None)
    stopped = SimpleNamespace(metrics={}, error=None)
    grid = Grid([reported, stopped])
    grid._experiment_analysis = SimpleNamespace(
        trials=[
            SimpleNamespace(config={"train.steps": 40}, trial_id="t_00000"),
            SimpleNamespace(config={"train.steps": 600}, trial_id="t_00001"),
        ]
    )
    assert tune_trials(grid) == [
        ({"train.steps": 40}, reported.metrics, None),
        ({"train.steps": 600}, {"trial_id": "t_00001"}, None),
    ]
