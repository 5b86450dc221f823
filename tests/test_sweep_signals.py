"""`drivestack sweep` stopped (issue 36): SIGTERM, or Ctrl-C on a terminal (SIGINT to the process
group, twice), while its trials train ends with the finished trials kept, the report written, exit
code 130 and no message from Ray, also before the trials run; a SIGKILL leaves no process of the
sweep alive. Either way `sweep --resume` finishes the sweep. Each case starts its own Ray instance
(slow)."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from stack.runtime.interrupts import STOPPING
from stack.runtime.watchdog import descendants
from tests.test_signals import outliving
from tests.test_train import TINY

pytest.importorskip("ray")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc"),
]

SHORT, LONG = 40, 600
"""Training steps of the two trials: one finishes soon, the other is still training when stopped."""


def sweep_file(tmp_path: Path, steps: tuple[int, ...] = (SHORT, LONG)) -> Path:
    base = {
        **TINY,
        "planner": {"agent": "ddqn"},
        "train": {**TINY["train"], "validation": {**TINY["train"]["validation"], "long_every": 100}},
    }
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"config": "base.yaml", "space": {"train.steps": list(steps)}}))
    return path


def sweep_process(spec: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "stack", "sweep", "--config", str(spec), "--out", str(out), "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def started_sweep(tmp_path: Path, out: Path) -> subprocess.Popen:
    """The sweep, returned once one trial has finished and the other has saved a checkpoint."""
    process = sweep_process(sweep_file(tmp_path), out)
    deadline = time.monotonic() + 600
    while True:
        trials = list((out / "trials").glob("*")) if (out / "trials").is_dir() else []
        finished = [t for t in trials if (t / "summary.json").is_file()]
        training = [t for t in trials if (t / "checkpoint.npz").is_file() and t not in finished]
        if finished and training:
            return process
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.2)


def resumed(out: Path) -> dict:
    """`sweep --resume OUT` run to its end: its summary."""
    done = subprocess.run(
        [sys.executable, "-m", "stack", "sweep", "--resume", str(out), "--no-progress"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("stop", ["sigterm", "ctrl-c twice"])
def test_a_stopped_sweep_keeps_its_finished_trials_exits_130_and_resumes(tmp_path, stop):
    out = tmp_path / "sweep"
    process = started_sweep(tmp_path, out)
    processes = descendants(process.pid)
    if stop == "sigterm":
        process.send_signal(signal.SIGTERM)
    else:
        os.killpg(process.pid, signal.SIGINT)
        time.sleep(0.05)
        os.killpg(process.pid, signal.SIGINT)
    output, errors = process.communicate(timeout=300)
    assert process.returncode == 130, errors
    assert errors.strip() in ("", STOPPING), errors
    assert output.strip().splitlines()[-1] == (
        f"results: {out} (unfinished trials: `drivestack sweep --resume {out}` continues them)"
    )
    assert not outliving(processes, 15), "no Ray process outlives the sweep"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["trials"] == 2 and summary["finished"] == 1
    with (out / "trials.csv").open() as handle:
        rows = {int(row["train.steps"]): row for row in csv.DictReader(handle)}
    assert rows[SHORT]["status"] == "finished" and int(rows[SHORT]["steps"]) == SHORT
    assert rows[LONG]["status"] == "unfinished"

    again = resumed(out)
    assert again["finished"] == 2 and not again["interrupted"]


def test_a_killed_sweep_leaves_no_process_and_resumes(tmp_path):
    out = tmp_path / "sweep"
    process = started_sweep(tmp_path, out)
    processes = descendants(process.pid)
    assert len(processes) >= 4, "Ray's processes and the trials' workers"
    process.kill()
    process.communicate(timeout=60)
    assert not outliving(processes, 15), "no process of the killed sweep lives on"
    assert resumed(out)["finished"] == 2


def ray_starting(out: Path, pid: int) -> bool:
    """Whether the sweep is starting Ray (the watchdog, then Ray's processes, are its children)."""
    return bool(descendants(pid))


def tune_starting(out: Path, pid: int) -> bool:
    """Whether the sweep has prepared its folder (Ray runs; Tune sets up or starts the trials)."""
    return (out / "sweep.yaml").is_file()


@pytest.mark.parametrize("moment", [ray_starting, tune_starting])
def test_a_sweep_stopped_before_its_trials_run_exits_130_and_leaves_nothing_running(tmp_path, moment):
    """SIGTERM while Ray starts, or while Tune sets up: exit 130, at most one line on stderr and no
    traceback or message from Ray, no process left; a folder the sweep prepared resumes."""
    out = tmp_path / "sweep"
    process = sweep_process(sweep_file(tmp_path, (SHORT,)), out)
    seen: set[int] = set()
    sent = False
    while process.poll() is None:
        seen.update(descendants(process.pid))
        if not sent and moment(out, process.pid):
            process.send_signal(signal.SIGTERM)
            sent = True
        time.sleep(0.02)
    _, errors = process.communicate()
    assert sent and process.returncode == 130, errors
    assert len(errors.strip().splitlines()) <= 1, errors
    assert "Traceback" not in errors and "SIGTERM" not in errors, errors
    assert not outliving(sorted(seen), 15), "no process of the sweep lives on"
    assert (out / "sweep.yaml").is_file() == (moment is tune_starting)
    if moment is tune_starting:
        assert resumed(out)["finished"] == 1
