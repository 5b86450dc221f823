"""Nothing finished is lost: SIGTERM or Ctrl-C, once or twice, during `run` and `compare` leaves
every finished episode readable (journaled as it finishes, results written whole) and exits 130."""

import csv
import json
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.core import episodes, interrupts
from stack.core.files import EpisodeJournal, replacing, write_text
from stack.core.metrics import outcome

SHORT = ["--set", "highway.duration=4", "--set", "highway.vehicles_count=8", "--no-progress"]


def stopped_after_first_episode(arguments: list[str], journal: Path, sig: signal.Signals) -> int:
    """Start the CLI, wait until `journal` holds a finished episode, send `sig` twice 50 ms apart;
    the exit code."""
    process = subprocess.Popen(
        [sys.executable, "-m", "stack", *arguments], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    deadline = time.monotonic() + 120
    while not (journal.is_file() and journal.read_text().count("\n") >= 1):
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.05)
    process.send_signal(sig)
    time.sleep(0.05)
    process.send_signal(sig)
    _, errors = process.communicate(timeout=120)
    assert "Traceback" not in errors.decode(), errors.decode()
    return process.returncode


def untimed(path: Path) -> list[dict]:
    """The rows of a results file (summary.json, comparison.json, episodes.csv) without their
    wall-clock timing fields (`outcome`)."""
    loaded = list(csv.DictReader(path.open())) if path.suffix == ".csv" else json.loads(path.read_text())
    return [outcome(row) for row in (loaded if isinstance(loaded, list) else [loaded])]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_stopped_run_keeps_its_finished_episodes_and_resume_finishes_it(tmp_path, sig):
    out = tmp_path / "run"
    arguments = ["run", "--agent", "keep-lane", "--episodes", "40", *SHORT]
    journal = out / "keep-lane.episodes.partial.jsonl"
    assert stopped_after_first_episode([*arguments, "--out", str(out)], journal, sig) == 130
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and 1 <= summary["episodes"] < 40
    assert len((out / "episodes.csv").read_text().splitlines()) == summary["episodes"] + 1
    assert sorted(p.name for p in out.iterdir()) == [
        "config.yaml",
        "episodes.csv",
        "grid.png",
        journal.name,
        "summary.json",
        "traces.png",
    ]
    other = CliRunner().invoke(app, [*arguments, "--seed", "5", "--out", str(out), "--resume"])
    assert other.exit_code == 2 and "is another run's" in other.output
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume"])
    assert resumed.exit_code == 0 and not journal.exists(), resumed.output
    whole = CliRunner().invoke(app, [*arguments, "--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    assert untimed(out / "summary.json") == untimed(tmp_path / "whole" / "summary.json")
    assert untimed(out / "episodes.csv") == untimed(tmp_path / "whole" / "episodes.csv")


def test_a_stopped_comparison_keeps_the_agents_run_so_far_and_resume_finishes_it(tmp_path, monkeypatch):
    out = tmp_path / "compare"
    arguments = ["compare", "--agents", "keep-lane,rule", "--episodes", "30", *SHORT]
    journal = out / "rule.episodes.partial.jsonl"
    assert stopped_after_first_episode([*arguments, "--out", str(out)], journal, signal.SIGTERM) == 130
    rows = json.loads((out / "comparison.json").read_text())
    assert [row["agent"] for row in rows] == ["keep-lane", "rule"]
    assert rows[0]["episodes"] == 30 and 1 <= rows[1]["episodes"] < 30 and rows[1]["interrupted"]
    assert (out / "comparison.png").is_file() and journal.is_file()

    other = CliRunner().invoke(app, [*arguments, "--seed", "5", "--out", str(out), "--resume"])
    assert (
        other.exit_code == 2
        and other.output.startswith("error: --resume: ")
        and "is another run's" in other.output
    )
    with journal.open("a") as handle:
        handle.write('{"episode": 3, "seed": 1, "ste')
    ran: list[int] = []
    real = episodes.run_episode
    monkeypatch.setattr(episodes, "run_episode", lambda c, e, f=None: ran.append(e) or real(c, e, f))
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert len(ran) == 30 - rows[1]["episodes"] and not list(out.glob("*.partial*"))
    monkeypatch.undo()
    whole = CliRunner().invoke(app, [*arguments, "--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    resumed_rows = untimed(out / "comparison.json")
    assert resumed_rows == untimed(tmp_path / "whole" / "comparison.json")
    assert resumed_rows[1]["episodes"] == 30


def test_a_second_signal_waits_for_the_results_being_written(monkeypatch):
    monkeypatch.setattr(interrupts, "_received", 0)
    with interrupts.deferred(interrupt_after=False):
        interrupts._handler(signal.SIGTERM, None)
        interrupts._handler(signal.SIGTERM, None)
    assert interrupts.received()
    monkeypatch.setattr(interrupts, "_received", 0)
    with pytest.raises(KeyboardInterrupt), interrupts.deferred():
        interrupts._handler(signal.SIGINT, None)
    with pytest.raises(KeyboardInterrupt):
        monkeypatch.setattr(interrupts, "_received", 0)
        interrupts._handler(signal.SIGINT, None)


def test_a_file_is_written_whole_or_left_as_it_was(tmp_path):
    path = tmp_path / "summary.json"
    write_text(path, "old")
    with pytest.raises(RuntimeError):
        with replacing(path) as part:
            part.write_text("half")
            raise RuntimeError
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["summary.json"]


def test_the_journal_is_on_disk_after_each_episode(tmp_path):
    journal = EpisodeJournal(tmp_path / "j.jsonl")
    for episode in (0, 1):
        journal.record(SimpleNamespace(row=lambda episode=episode: {"episode": episode}))
    assert [json.loads(line)["episode"] for line in (tmp_path / "j.jsonl").read_text().splitlines()] == [0, 1]
    journal.discard()
    assert not (tmp_path / "j.jsonl").exists()
