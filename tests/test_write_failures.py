"""Full and read-only disks (issue 36): a results file that cannot be written ends `run`, `compare`,
`track` and `train` with one line naming it and saying what was kept (exit 2, no traceback), no
temporary or half file is left, and what had finished is kept for `--resume`. A results folder
in a read-only place is refused before any work."""

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from matplotlib.figure import Figure
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.runtime import files
from tests.test_cli import tiny_config_file
from tests.test_hostile_inputs import one_line_refusal
from tests.test_train import TINY

FULL = errno.ENOSPC


def failing_figures(monkeypatch: pytest.MonkeyPatch, name: str, code: int = FULL) -> None:
    """Every figure whose file name holds `name` is written half, then the disk fails (`code`)."""
    real = Figure.savefig

    def savefig(self: Figure, path: object, *args: object, **kwargs: object) -> None:
        if name in str(path):
            Path(str(path)).write_bytes(b"half a figure")
            raise OSError(code, os.strerror(code))
        real(self, path, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)


def leftovers(folder: Path) -> list[str]:
    """Temporary files a writer left in `folder` (none must be)."""
    return sorted(p.name for p in folder.rglob("*") if ".partial" in p.name and "episodes" not in p.name)


def one_line_failure(arguments: list[str], expected: str) -> str:
    """`arguments` end with exit code 2 and one error line holding `expected` (a table may come
    before it); the line."""
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and "internal error" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and expected in errors[0], result.output
    return errors[0]


def run_arguments(tmp_path: Path, out: Path, *options: str) -> list[str]:
    config = str(tiny_config_file(tmp_path))
    return ["run", "-c", config, "--agent", "keep-lane", "--episodes", "2", *options, "--out", str(out)]


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EROFS])
def test_a_run_whose_figure_cannot_be_written_keeps_its_episodes_for_resume(tmp_path, monkeypatch, code):
    out = tmp_path / "run"
    arguments = run_arguments(tmp_path, out, "--no-progress")
    failing_figures(monkeypatch, "traces", code)
    line = one_line_failure(arguments, f"cannot write {out / 'traces.png'} ({os.strerror(code)})")
    assert "keep-lane.episodes.partial.jsonl" in line and "--resume" in line
    assert leftovers(out) == [] and not (out / "traces.png").exists()
    assert len((out / "keep-lane.episodes.partial.jsonl").read_text().splitlines()) == 2
    monkeypatch.undo()
    resumed = CliRunner().invoke(app, [*arguments, "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert json.loads((out / "summary.json").read_text())["episodes"] == 2


def test_a_journal_line_that_cannot_be_written_is_cut_off_and_the_lines_before_kept(tmp_path, monkeypatch):
    out = tmp_path / "run"
    arguments = run_arguments(tmp_path, out, "--no-progress")
    synced = []

    def fsync(descriptor: int) -> None:
        synced.append(descriptor)
        if len(synced) == 2:
            raise OSError(FULL, os.strerror(FULL))

    monkeypatch.setattr(files.os, "fsync", fsync)
    journal = out / "keep-lane.episodes.partial.jsonl"
    one_line_failure(arguments, f"cannot write {journal} (No space left on device)")
    rows = [json.loads(line) for line in journal.read_text().splitlines()]
    assert [row["episode"] for row in rows] == [0]
    monkeypatch.undo()
    resumed = CliRunner().invoke(app, [*arguments, "--resume"])
    assert resumed.exit_code == 0 and "dropped" not in resumed.output, resumed.output
    assert json.loads((out / "summary.json").read_text())["episodes"] == 2


def test_a_comparison_whose_figure_cannot_be_written_keeps_every_journal(tmp_path, monkeypatch):
    out = tmp_path / "compare"
    config = str(tiny_config_file(tmp_path))
    arguments = ["compare", "-c", config, "--agents", "keep-lane,rule", "--episodes", "1", "--out", str(out)]
    failing_figures(monkeypatch, "comparison")
    line = one_line_failure([*arguments, "--no-progress"], "comparison.png (No space left on device)")
    assert "keep-lane.episodes.partial.jsonl, rule.episodes.partial.jsonl" in line
    assert leftovers(out) == [] and not (out / "comparison.png").exists()
    monkeypatch.undo()
    resumed = CliRunner().invoke(app, [*arguments, "--resume", "--no-progress"])
    assert resumed.exit_code == 0 and (out / "comparison.png").is_file(), resumed.output


def test_track_prints_its_table_before_a_figure_fails(tmp_path, monkeypatch):
    out = tmp_path / "track"
    failing_figures(monkeypatch, "tracking_straight")
    arguments = ["track", "--controller", "pid", "--plant", "kinematic", "--speeds", "20", "--out", str(out)]
    result = CliRunner().invoke(app, [*arguments, "--no-progress"])
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert "lane changes (worst of left and right)" in result.output
    assert "the table above holds every maneuver measured" in result.output.splitlines()[-1]
    assert leftovers(out) == []


def tiny_training(tmp_path: Path) -> list[str]:
    (config := tmp_path / "tiny-train.yaml").write_text(yaml.safe_dump(TINY))
    return ["train", "-c", str(config), "--out", str(tmp_path / "train"), "--no-progress"]


def failing_model_files(monkeypatch: pytest.MonkeyPatch, name: str, after: int = 0) -> None:
    """The model file `name` (checkpoint.npz, final.npz) fails as on a full disk, half written,
    from its `after`+1-th write on."""
    real, writes = np.savez, []

    def savez(handle: object, **arrays: object) -> None:
        if Path(handle.name).name == f"{name}.partial":  # type: ignore[attr-defined]
            writes.append(1)
            if len(writes) > after:
                handle.write(b"half")  # type: ignore[attr-defined]
                raise OSError(FULL, os.strerror(FULL))
        real(handle, **arrays)

    monkeypatch.setattr(np, "savez", savez)


def test_a_training_whose_checkpoint_cannot_be_written_resumes_from_the_last_one(tmp_path, monkeypatch):
    arguments, folder = tiny_training(tmp_path), tmp_path / "train"
    failing_model_files(monkeypatch, "checkpoint.npz", after=1)
    line = one_line_failure(arguments, f"cannot write {folder / 'checkpoint.npz'} (No space left")
    assert "its last checkpoint (step 10) is kept" in line and f"--resume {folder}" in line
    assert leftovers(folder) == [] and not (folder / "summary.json").exists()
    monkeypatch.undo()
    resumed = CliRunner().invoke(app, ["train", "--resume", str(folder), "--no-progress"])
    assert resumed.exit_code == 0, resumed.output
    assert json.loads((folder / "summary.json").read_text())["steps"] == 40


def test_a_finished_training_whose_last_files_failed_writes_them_on_resume(tmp_path, monkeypatch):
    arguments, folder = tiny_training(tmp_path), tmp_path / "train"
    failing_model_files(monkeypatch, "final.npz")
    line = one_line_failure(arguments, f"cannot write {folder / 'final.npz'}")
    assert "its 40 steps are trained and checkpointed" in line and "writes the files still missing" in line
    assert leftovers(folder) == [] and not (folder / "final.npz").exists()
    monkeypatch.undo()
    resumed = CliRunner().invoke(app, ["train", "--resume", str(folder), "--no-progress"])
    assert resumed.exit_code == 0, resumed.output
    assert json.loads((folder / "summary.json").read_text())["interrupted"] is False
    assert (folder / "final.npz").is_file()
    one_line_refusal(["train", "--resume", str(folder)], "finished its 40 steps; nothing to resume")


def read_only(folder: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """`folder`, made read-only; where the user may write it all the same (root), writing checks
    see it as a read-only filesystem shows it."""
    folder.mkdir(exist_ok=True)
    folder.chmod(0o555)
    if os.access(folder, os.W_OK):
        real = os.access

        def access(path: object, mode: int, **options: object) -> bool:
            denied = mode & os.W_OK and Path(str(path)).absolute() == folder.absolute()
            return not denied and real(path, mode, **options)  # type: ignore[arg-type]

        monkeypatch.setattr(os, "access", access)
    return folder


@pytest.mark.parametrize(
    "command",
    [
        ["run", "--agent", "keep-lane"],
        ["compare", "--agents", "keep-lane"],
        ["track", "--controller", "pid"],
        ["train"],
        ["safety", "--quick"],
        ["reproduce", "deepcars", "--quick"],
    ],
    ids=lambda command: command[0] if command[0] != "reproduce" else "reproduce",
)
def test_a_results_folder_in_a_read_only_place_is_refused_before_any_work(tmp_path, monkeypatch, command):
    locked = read_only(tmp_path / "locked", monkeypatch)
    try:
        one_line_refusal([*command, "--out", str(locked / "results")], f"--out: {locked} is not writable")
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o755)


def test_resuming_a_folder_made_read_only_is_refused_before_any_work(tmp_path, monkeypatch):
    from tests.test_folders import training_folder

    folder = training_folder(tmp_path)
    before = sorted(p.name for p in folder.iterdir())
    read_only(folder, monkeypatch)
    try:
        one_line_refusal(["train", "--resume", str(folder)], f"--out: {folder} is not writable")
        assert sorted(p.name for p in folder.iterdir()) == before
    finally:
        folder.chmod(0o755)


def test_a_write_failure_anywhere_else_is_one_line_not_an_internal_error(capsys):
    import typer

    from stack.apps.options import guarded

    broken = typer.Typer()

    @broken.command()
    def write() -> None:
        raise files.WriteFailed(FULL, os.strerror(FULL), "runs/x/summary.json")

    with pytest.raises(SystemExit) as stopped:
        guarded(broken, [])
    assert stopped.value.code == 2
    assert capsys.readouterr().err == "error: cannot write runs/x/summary.json (No space left on device)\n"
