"""Hostile configs and locations: one line, exit 2, before any work (issue: hardening)."""

from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from stack.apps.cli import app
from tests.test_cli import tiny_config_file

BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n" + "".join(
    f"{chr(99 + i)}: &{chr(99 + i)} [{', '.join([f'*{chr(98 + i)}'] * 9)}]\n" for i in range(7)
)


def one_line_refusal(arguments: list[str], expected: str) -> None:
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 2, result.output
    assert expected in result.output, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and len(lines[0]) <= 300, result.output[:500]


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (BOMB + "seed: *i\n", "anchors and aliases (&, *) are not accepted"),
        (BOMB + "perception: {features: *i}\n", "anchors and aliases (&, *) are not accepted"),
        ("decision_period_s: .inf\n", "decision_period_s"),
        ("seed: 1180591620717411303424\n", "seed: Input should be less than or equal to"),
        (
            "perception: {cells_ahead: 100000000}\n",
            "perception.cells_ahead: Input should be less than or equal to 200",
        ),
        ("highway: {duration: .inf}\n", "highway.duration"),
        ("perception: {sensor: {false_positives: 1.0e+12}}\n", "false_positives: Input should be less than"),
        (
            "perception: {features: [" + "ttc, " * 20_000 + "]}\n",
            "perception.features: Tuple should have at most 5",
        ),
    ],
)
def test_hostile_configs_are_refused_in_one_line(tmp_path, content, expected):
    path = tmp_path / "hostile.yaml"
    path.write_text(content)
    one_line_refusal(["run", "-c", str(path), "--out", str(tmp_path / "out")], expected)
    assert not (tmp_path / "out").exists()


def test_a_config_that_is_not_utf8_or_too_large_is_refused(tmp_path):
    binary = tmp_path / "latin.yaml"
    binary.write_bytes(b"seed: 1 # caf\xe9\n")
    one_line_refusal(["run", "-c", str(binary)], "not UTF-8 text")
    large = tmp_path / "large.yaml"
    large.write_text("# " + "x" * 2_000_000 + "\n")
    one_line_refusal(["run", "-c", str(large)], "a config is at most")


def test_output_locations_are_checked_before_any_work(tmp_path):
    config = str(tiny_config_file(tmp_path))
    existing = tmp_path / "results.txt"
    existing.write_text("keep me")
    for command in (["run"], ["compare", "--agents", "keep-lane"], ["track", "--controller", "pid"]):
        one_line_refusal([*command, "-c", config, "--out", str(existing)], "is a file; expected a folder")
    assert existing.read_text() == "keep me"
    one_line_refusal(
        ["run", "-c", config, "--out", str(existing / "below" / "a file")], "--out: cannot create"
    )


def test_a_replay_buffer_larger_than_memory_is_refused_before_allocation(tmp_path):
    config = tmp_path / "train.yaml"
    config.write_text(
        yaml.safe_dump({"train": {"buffer_size": 50_000_000}, "perception": {"cells_ahead": 200}})
    )
    one_line_refusal(
        ["train", "-c", str(config), "--out", str(tmp_path / "t")], "train.buffer_size: 50000000"
    )
    assert not (tmp_path / "t").exists()


def test_demonstrations_larger_than_memory_are_refused_before_any_episode(tmp_path):
    config = tmp_path / "train.yaml"
    config.write_text(
        yaml.safe_dump({"highway": {"duration": 3600}, "train": {"demonstrations": {"episodes": 100_000}}})
    )
    one_line_refusal(
        ["train", "-c", str(config), "--out", str(tmp_path / "t")], "train.demonstrations.episodes: 100000"
    )
    assert not (tmp_path / "t").exists()


def owned_training_folder(folder: Path, config: dict) -> None:
    """`folder` as `train` starts it: its config.yaml and its owner record."""
    import json
    from dataclasses import asdict

    from stack.apps.training import training_owner
    from stack.runtime.owner import MARKER
    from stack.settings.run import load_config

    folder.mkdir()
    (folder / "config.yaml").write_text(yaml.safe_dump(config))
    (folder / MARKER).write_text(json.dumps(asdict(training_owner(load_config(folder / "config.yaml")))))


def test_resume_from_a_broken_or_foreign_checkpoint_is_one_line(tmp_path):
    from planner.factory import SHIPPED_MODELS

    folder = tmp_path / "run"
    owned_training_folder(folder, {"train": {"steps": 10}, "highway": {"duration": 2}})
    (folder / "checkpoint.npz").write_bytes(SHIPPED_MODELS["ddqn"].read_bytes())
    one_line_refusal(["train", "--resume", str(folder), "--no-progress"], "not a training checkpoint")
    (folder / "checkpoint.npz").write_bytes(SHIPPED_MODELS["ddqn"].read_bytes()[:5000])
    one_line_refusal(["train", "--resume", str(folder), "--no-progress"], "not a drivestack model file")


def test_an_unforeseen_failure_is_one_line_pointing_at_debug(capsys):
    import typer

    from stack.apps.options import guarded

    broken = typer.Typer()

    @broken.command()
    def explode() -> None:
        raise RuntimeError("the flux capacitor\nis empty")

    with pytest.raises(SystemExit) as stopped:
        guarded(broken, [])
    assert stopped.value.code == 1
    assert capsys.readouterr().err == (
        "internal error: RuntimeError: the flux capacitor (run with --debug for the traceback)\n"
    )
    with pytest.raises(RuntimeError):
        guarded(broken, ["--debug"])


def test_train_refuses_an_output_file_before_importing_torch(tmp_path):
    import subprocess
    import sys

    existing = tmp_path / "results.txt"
    existing.write_text("keep me")
    probe = (
        "import sys\nfrom stack.apps.cli import app\n"
        f"try:\n    app(['train', '--out', {str(existing)!r}])\n"
        "except SystemExit as stop:\n"
        "    print(stop.code, 'torch' in sys.modules, 'stable_baselines3' in sys.modules)\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert result.stdout.split() == ["2", "False", "False"], result.stderr
