"""One owner per results folder (issue 36, defects 1-4): another command, a concurrent writer, a
changed config on `--resume` or a fresh command into a folder it does not own is refused in one
line, and the folder is left exactly as it was."""

import json
from dataclasses import asdict
from pathlib import Path

import yaml
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.apps.training import training_owner
from stack.runtime.owner import MARKER, Owner, claim
from stack.settings.run import load_config, write_config
from tests.test_cli import tiny_config_file
from tests.test_hostile_inputs import one_line_refusal
from tests.test_train import TINY


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file of `folder` with its bytes (the lock file aside: it only names the last writer)."""
    return {
        p.name: p.read_bytes()
        for p in sorted(folder.iterdir())
        if p.is_file() and p.name != ".drivestack.lock"
    }


def finished_run(tmp_path: Path, *options: str) -> tuple[Path, list[str]]:
    out = tmp_path / "run"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), "--agent", "keep-lane", "--episodes", "1"]
    result = CliRunner().invoke(app, [*arguments, *options, "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    return out, arguments


def training_folder(tmp_path: Path) -> Path:
    """A training run's folder as `train` leaves it before its first checkpoint: config and owner."""
    source = tmp_path / "tiny-train.yaml"
    source.write_text(yaml.safe_dump(TINY))
    config = load_config(source)
    folder = tmp_path / "train"
    folder.mkdir()
    write_config(config, folder / "config.yaml")
    (folder / MARKER).write_text(json.dumps(asdict(training_owner(config))))
    return folder


def test_train_resume_refuses_a_run_folder_and_leaves_it_as_it_was(tmp_path):
    out, _ = finished_run(tmp_path)
    before = snapshot(out)
    one_line_refusal(["train", "--resume", str(out)], "holds the results of `run`, not a training run")
    (out / MARKER).unlink()
    before.pop(MARKER)
    one_line_refusal(["train", "--resume", str(out)], "is not a training run folder")
    assert snapshot(out) == before


def test_another_command_or_other_arguments_into_a_results_folder_are_refused(tmp_path):
    out, arguments = finished_run(tmp_path)
    before = snapshot(out)
    config = str(tiny_config_file(tmp_path))
    for command, expected in (
        (["compare", "-c", config, "--agents", "keep-lane"], "already holds the results of `run`"),
        ([*arguments, "--seed", "3"], "already holds the results of `run` with other arguments"),
        (["track", "--controller", "pid", "--speeds", "20"], "already holds the results of `run`"),
        (["train", "-c", config], "already holds the results of `run`"),
        (["compare", "-c", config, "--agents", "keep-lane", "--resume"], "not of `compare`"),
    ):
        one_line_refusal([*command, "--out", str(out)], expected)
    assert snapshot(out) == before
    again = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert again.exit_code == 0, "the same command starts over in its own folder"


def test_a_folder_drivestack_did_not_write_is_refused(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    config = str(tiny_config_file(tmp_path))
    one_line_refusal(["run", "-c", config, "--out", str(out)], "already holds files drivestack did not write")
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_a_second_writer_is_refused_while_the_first_holds_the_folder(tmp_path):
    out = tmp_path / "busy"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), "--agent", "keep-lane", "--episodes", "1"]
    lock = claim(out, Owner("run", "x"), resuming=False)
    try:
        one_line_refusal([*arguments, "--out", str(out)], "is being written by another drivestack command")
    finally:
        lock.close()
    assert not (out / "config.yaml").exists()


def test_train_resume_refuses_a_changed_config_before_writing_anything(tmp_path):
    folder = training_folder(tmp_path)
    before = snapshot(folder)
    for options, expected in (
        (["--set", "train.gamma=0.5"], "--set train.gamma: the run in"),
        (["--set", "train.network=16x16"], "--set train.network: the run in"),
        (["--set", "train.reward.collision=-5"], "--set train.reward.collision"),
        (["--envs", "2"], "--envs: has no effect with --resume"),
        (["--seed", "3"], "--seed: has no effect with --resume"),
        (["--steps", "20"], "--steps: expected at least 40"),
    ):
        one_line_refusal(["train", "--resume", str(folder), *options, "--no-progress"], expected)
    assert snapshot(folder) == before
    config = folder / "config.yaml"
    config.write_text(config.read_text().replace("gamma: 0.95", "gamma: 0.5"))
    assert "gamma: 0.5" in config.read_text()
    one_line_refusal(["train", "--resume", str(folder)], "is another run's")


def test_a_fresh_training_into_a_training_folder_is_refused(tmp_path):
    folder = training_folder(tmp_path)
    before = snapshot(folder)
    source = tmp_path / "tiny-train.yaml"
    one_line_refusal(
        ["train", "-c", str(source), "--out", str(folder)], "already holds the results of `train`"
    )
    assert snapshot(folder) == before


def test_train_resume_of_a_folder_without_an_owner_record_is_refused_unless_adopted(tmp_path):
    """A training folder from before owner records: refused with the way on; `--adopt` takes it
    over once config.yaml agrees with what the run's files recorded."""
    source = tmp_path / "tiny-train.yaml"
    source.write_text(yaml.safe_dump({**TINY, "train": {**TINY["train"], "steps": 20}}))
    folder = tmp_path / "old"
    trained = CliRunner().invoke(app, ["train", "-c", str(source), "--out", str(folder), "--no-progress"])
    assert trained.exit_code == 0, trained.output
    (folder / MARKER).unlink()
    before, config = snapshot(folder), folder / "config.yaml"
    one_line_refusal(
        ["train", "--resume", str(folder)],
        f"records no owner (made before {MARKER} existed); if its config.yaml is the one it was "
        "trained with, add --adopt",
    )
    one_line_refusal(["train", "-c", str(source), "--adopt"], "--adopt: has no effect without --resume")
    text = config.read_text()
    for changed, expected in (
        (text.replace("learning_rate: 0.0005", "learning_rate: 0.001"), "checkpoint.npz learning rate was"),
        (text.replace("network: '16'", "network: 16x16"), "best.npz network was trained with '16'"),
        (
            text.replace("seed: 1\n", "seed: 2\n", 1),
            "best.npz seed was trained with 1, but config.yaml says 2",
        ),
    ):
        config.write_text(changed)
        one_line_refusal(["train", "--resume", str(folder), "--adopt"], expected)
    config.write_text(text)
    (folder / "episodes.csv").write_text("episode\n")
    one_line_refusal(
        ["train", "--resume", str(folder), "--adopt"], "holds episodes.csv, which no training run"
    )
    (folder / "episodes.csv").unlink()
    assert snapshot(folder) == before
    adopted = CliRunner().invoke(
        app, ["train", "--resume", str(folder), "--adopt", "--steps", "30", "--no-progress"]
    )
    assert adopted.exit_code == 0, adopted.output
    assert json.loads((folder / "summary.json").read_text())["steps"] == 30
    assert json.loads((folder / MARKER).read_text())["command"] == "train"
    one_line_refusal(["train", "--resume", str(folder), "--adopt"], "already records its owner")


def test_a_training_started_with_world_sets_over_a_scenario_resumes_in_that_world(tmp_path):
    """Issue 52 (3, 4): the folder's config.yaml reads back as the run's config, so `--resume`
    finds its own run (it used to answer "is another run's" and, adopted, trained in the
    scenario's 40-s world)."""
    source = tmp_path / "tiny-train.yaml"
    source.write_text(yaml.safe_dump({**TINY, "train": {**TINY["train"], "steps": 20}}))
    folder = tmp_path / "train"
    world = ["--scenario", "overtaking", "--set", "highway.duration=4", "--set", "highway.vehicles_count=9"]
    first = CliRunner().invoke(
        app, ["train", "-c", str(source), *world, "--out", str(folder), "--no-progress"]
    )
    assert first.exit_code == 0, first.output
    resumed = CliRunner().invoke(app, ["train", "--resume", str(folder), "--steps", "40", "--no-progress"])
    assert resumed.exit_code == 0, resumed.output
    config = load_config(folder / "config.yaml")
    assert (config.scenario, config.highway.duration, config.highway.vehicles_count) == ("overtaking", 4, 9)
    assert json.loads((folder / "summary.json").read_text())["steps"] == 40
