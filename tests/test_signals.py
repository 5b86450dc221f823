"""Nothing finished is lost: SIGTERM or Ctrl-C, once or twice, during `run` and `compare` leaves
every finished episode readable (journaled as it finishes, results written whole) and exits 130."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from stack.apps import track as track_module
from stack.apps.cli import app
from stack.apps.run import undrawn
from stack.results.episode_result import outcome
from stack.runs import episodes
from stack.runtime import executors, interrupts, watchdog
from stack.runtime.files import EpisodeJournal, replacing, write_text
from tests.test_cli import tiny_config_file

SHORT = ["--set", "highway.duration=4", "--set", "highway.vehicles_count=8", "--no-progress"]
ONE_AT_A_TIME = ["--set", "sim.batched=false"]
"""Episodes one world at a time: a short batch of them ends before a test's signal reaches it."""


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


@pytest.mark.parametrize(
    "sig",
    [signal.SIGTERM, pytest.param(signal.SIGINT, marks=pytest.mark.slow)],
    ids=["SIGTERM", "SIGINT"],
)
def test_a_stopped_run_keeps_its_finished_episodes_and_resume_finishes_it(tmp_path, sig):
    """(SIGINT takes the same path; Ctrl-C itself has its own tests below.)"""
    out = tmp_path / "run"
    arguments = ["run", "--agent", "keep-lane", "--episodes", "16", *SHORT]
    journal = out / "keep-lane.episodes.partial.jsonl"
    assert stopped_after_first_episode([*arguments, "--out", str(out)], journal, sig) == 130
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and 1 <= summary["episodes"] < 16
    assert len((out / "episodes.csv").read_text().splitlines()) == summary["episodes"] + 1
    assert sorted(p.name for p in out.iterdir()) == [
        ".drivestack-owner.json",
        ".drivestack.lock",
        "config.yaml",
        "episodes.csv",
        "grid.png",
        journal.name,
        "summary.json",
        "timings.csv",
        "traces.png",
    ]
    other = CliRunner().invoke(app, [*arguments, "--seed", "5", "--out", str(out), "--resume"])
    assert other.exit_code == 2 and "is another run's" in other.output
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume"])
    assert resumed.exit_code == 0 and not journal.exists(), resumed.output
    whole = CliRunner().invoke(app, [*arguments, "--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    assert untimed(out / "summary.json") == untimed(tmp_path / "whole" / "summary.json")
    assert (out / "episodes.csv").read_bytes() == (tmp_path / "whole" / "episodes.csv").read_bytes()


def test_a_stopped_comparison_keeps_the_agents_run_so_far_and_resume_finishes_it(tmp_path, monkeypatch):
    out = tmp_path / "compare"
    arguments = ["compare", "--agents", "keep-lane,rule", "--episodes", "12", *SHORT, *ONE_AT_A_TIME]
    journal = out / "rule.episodes.partial.jsonl"
    assert stopped_after_first_episode([*arguments, "--out", str(out)], journal, signal.SIGTERM) == 130
    rows = json.loads((out / "comparison.json").read_text())
    assert [row["agent"] for row in rows] == ["keep-lane", "rule"]
    assert rows[0]["episodes"] == 12 and 1 <= rows[1]["episodes"] < 12 and rows[1]["interrupted"]
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
    monkeypatch.setattr(
        episodes, "run_episode", lambda c, e, *more, **kw: ran.append(e) or real(c, e, *more, **kw)
    )
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert len(ran) == 12 - rows[1]["episodes"] and not list(out.glob("*.partial*"))
    monkeypatch.undo()
    whole = CliRunner().invoke(app, [*arguments, "--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    resumed_rows = untimed(out / "comparison.json")
    assert resumed_rows == untimed(tmp_path / "whole" / "comparison.json")
    assert resumed_rows[1]["episodes"] == 12


def test_a_second_signal_waits_for_the_results_being_written(monkeypatch):
    monkeypatch.setattr(interrupts, "_raised", False)
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


def test_a_stop_lost_in_a_finalizer_still_ends_the_work_at_the_next_item(monkeypatch):
    """A first signal whose KeyboardInterrupt lands in a finalizer is printed and ignored by Python;
    `completed` raises it again before the next item, so the episodes stop there."""
    monkeypatch.setattr(interrupts, "_raised", False)
    monkeypatch.setattr(interrupts, "_received", 0)

    class Stopped:
        def __del__(self):
            interrupts._handler(signal.SIGTERM, None)

    def episode(item):
        Stopped()
        return item

    ran = []
    with pytest.raises(KeyboardInterrupt):
        for _, result in executors.completed(episode, [0, 1, 2]):
            ran.append(result)
    assert ran == [0], "the episode the stop was lost in finished; none started after it"
    assert interrupts.received()


def test_a_stop_lost_in_a_finalizer_is_not_printed_as_a_traceback(capsys, monkeypatch):
    """The CLI's `sys.unraisablehook` keeps Python from printing a first signal's KeyboardInterrupt
    lost in a finalizer ("Exception ignored ... Traceback"); any other lost exception is printed."""
    stops = interrupts.StopSignals()
    monkeypatch.setattr(sys, "unraisablehook", stops.unraisable)

    class Lost:
        def __init__(self, error: BaseException) -> None:
            self.error = error

        def __del__(self) -> None:
            raise self.error

    def lose(error: BaseException) -> None:
        Lost(error)

    lose(KeyboardInterrupt())
    assert "KeyboardInterrupt" in capsys.readouterr().err, "no stop was raised: Python's own hook"
    stops.raised = True
    lose(KeyboardInterrupt())
    assert capsys.readouterr().err == ""
    lose(RuntimeError("broken"))
    assert "RuntimeError: broken" in capsys.readouterr().err


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


def children(pid: int) -> list[int]:
    """The pids of `pid`'s child processes (Linux /proc)."""
    found = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    return [int(child) for child in found]


def alive(pid: int) -> bool:
    """Whether process `pid` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def outliving(pids: list[int], within_s: float = 10) -> list[int]:
    """The processes of `pids` still alive `within_s` seconds from now (or as soon as none is)."""
    deadline = time.monotonic() + within_s
    while any(alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return [pid for pid in pids if alive(pid)]


def started_with_workers(arguments: list[str], journal: Path, **popen: object) -> subprocess.Popen:
    """`drivestack ARGUMENTS` started, returned once `journal` holds an episode (its workers run)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "stack", *arguments], stdout=subprocess.PIPE, stderr=subprocess.PIPE, **popen
    )
    deadline = time.monotonic() + 120
    while not (journal.is_file() and journal.read_text().count("\n") >= 1):
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.05)
    return process


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc")
def test_pool_workers_end_when_their_driver_is_killed(tmp_path):
    out = tmp_path / "run"
    arguments = ["run", "--agent", "keep-lane", "--episodes", "4000", "--jobs", "2", *SHORT, *ONE_AT_A_TIME]
    arguments += ["--out", str(out)]
    process = started_with_workers(arguments, out / "keep-lane.episodes.partial.jsonl")
    deadline = time.monotonic() + 60  # episode 0 runs in the driver, then the pool starts: wait for it
    while not (workers := children(process.pid)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert workers, "the run has its pool"
    process.kill()
    process.communicate(timeout=30)
    assert not outliving(workers)


def test_ctrl_c_on_a_terminal_during_jobs_shows_no_worker_traceback(tmp_path):
    out = tmp_path / "run"
    arguments = ["run", "--agent", "keep-lane", "--episodes", "4000", "--jobs", "2", *SHORT, *ONE_AT_A_TIME]
    arguments += ["--out", str(out)]
    process = started_with_workers(
        arguments, out / "keep-lane.episodes.partial.jsonl", start_new_session=True
    )
    os.killpg(process.pid, signal.SIGINT)
    _, errors = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in errors.decode(), errors.decode()
    assert json.loads((out / "summary.json").read_text())["interrupted"]


def test_an_interrupt_before_the_first_episode_exits_130_and_resume_runs_it(tmp_path, monkeypatch):
    out = tmp_path / "run"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), "--agent", "keep-lane", "--episodes", "1"]

    def interrupted(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(episodes, "run_episode", interrupted)
    stopped = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert stopped.exit_code == 130 and "interrupted before anything finished" in stopped.output
    monkeypatch.undo()
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume", "--no-progress"])
    assert resumed.exit_code == 0, resumed.output
    assert json.loads((out / "summary.json").read_text())["episodes"] == 1


def test_an_interrupted_track_keeps_the_maneuvers_finished(tmp_path, monkeypatch):
    real = track_module._run_maneuver
    calls = []

    def two_then_interrupt(job):
        calls.append(job)
        if len(calls) > 2:
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(track_module, "_run_maneuver", two_then_interrupt)
    out = tmp_path / "track"
    arguments = ["track", "--controller", "pid", "--plant", "kinematic", "--speeds", "20"]
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert result.exit_code == 130 and "interrupted: the 2 of" in result.output
    assert len(json.loads((out / "tracking.json").read_text())) == 2


def test_a_resumed_run_says_what_it_could_not_draw(tmp_path):
    resumed = [SimpleNamespace(trace={}, snapshot=None)]
    (tmp_path / "grid.png").write_bytes(b"png")
    assert [
        note.split(":")[0] + ":" + note.split(":")[1].split("(")[0] for note in undrawn(tmp_path, resumed)
    ] == [
        "traces.png: not drawn ",
        "grid.png: kept from before --resume ",
    ]


def test_episodes_are_submitted_as_workers_free_up(monkeypatch):
    submitted = []
    real = executors.ProcessPoolExecutor.submit
    monkeypatch.setattr(
        executors.ProcessPoolExecutor, "submit", lambda pool, *a: submitted.append(a) or real(pool, *a)
    )
    monkeypatch.setattr(executors, "usable_cpus", lambda: 2)
    results = executors.completed(abs, list(range(-1000, 0)), jobs=64)
    next(results)
    assert len(submitted) <= 2 * executors.QUEUED_PER_WORKER + 1
    results.close()


def test_work_in_parts_starts_its_workers_once_and_ends_them_on_leaving(monkeypatch):
    monkeypatch.setattr(executors, "usable_cpus", lambda: 2)
    pools = []
    monkeypatch.setattr(
        executors, "ProcessPoolExecutor", lambda **kw: pools.append(ProcessPoolExecutor(**kw)) or pools[-1]
    )

    def workers(count):
        return {int(pid) for _, pid in executors.completed(os.readlink, ["/proc/self"] * count, jobs=2)}

    def alive(pid):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True

    with executors.shared_workers():
        first = workers(6)
        assert all(map(alive, first)), "kept for the next part"
        second = workers(6)
        assert len(pools) == 1 and os.getpid() not in first | second
    assert not any(map(alive, first | second)), "ended on leaving"
    alone = workers(4)
    assert len(pools) == 2 and not any(map(alive, alone)), "without it, each call has its own pool"


def test_work_that_stops_itself_is_asked_once_and_later_signals_wait(own_handlers, capsys):
    """`sweep`'s stop of Ray Tune's loop: the first signal asks the work to stop, later ones only say
    so; before the work can be asked, or after a stop that waited, the stop is a KeyboardInterrupt."""
    interrupts.catch_signals()
    asked = []
    with interrupts.stopped_by(lambda: asked.append(1) or True):
        os.kill(os.getpid(), signal.SIGTERM)
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGTERM)
    assert asked == [1] and interrupts.received()
    assert capsys.readouterr().err == f"{interrupts.STOPPING}\n" * 2
    interrupts.catch_signals()
    with pytest.raises(KeyboardInterrupt), interrupts.stopped_by(lambda: False):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    assert signal.getsignal(signal.SIGTERM) is interrupts._handler
    interrupts.catch_signals()
    with interrupts.deferred(interrupt_after=False):
        os.kill(os.getpid(), signal.SIGINT)
        with pytest.raises(KeyboardInterrupt), interrupts.stopped_by(lambda: asked.append(2) or True):
            pass
    assert asked == [1] and interrupts.received()


ORPHANS = """
import subprocess, sys, time
from stack.runtime.watchdog import watch_descendants
watch_descendants()
shell = subprocess.Popen(["sh", "-c", "sleep 600 & echo $!; wait"], stdout=subprocess.PIPE, text=True)
print(shell.pid, shell.stdout.readline().strip(), flush=True)
time.sleep(600)
"""


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc")
def test_the_watchdog_ends_what_a_killed_command_started():
    """A command killed by SIGKILL leaves processes that do not end with it (Ray's agents wait a
    minute for their dead GCS): the watchdog it started kills them, here a shell and its child."""
    process = subprocess.Popen([sys.executable, "-c", ORPHANS], stdout=subprocess.PIPE, text=True)
    started = [int(pid) for pid in process.stdout.readline().split()]
    assert len(started) == 2 and all(alive(pid) for pid in started)
    time.sleep(1.5 * watchdog.PERIOD_S)
    process.kill()
    process.communicate(timeout=30)
    assert not outliving(started)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_while_the_command_line_is_imported_ends_it_with_130_before_any_work(tmp_path, sig):
    """The entry point holds signals from its first line: a stop that comes while the CLI is still
    being imported (here: sent right after the hold, before the import) ends the command with exit
    130, no traceback and no folder, instead of SIGTERM's default exit 143."""
    out = tmp_path / "out"
    probe = (
        "import os, signal, sys\nimport stack.__main__ as entry\n"
        "entry.hold_signals()\n"
        f"os.kill(os.getpid(), {int(sig)})\n"
        f"sys.argv = ['drivestack', 'run', '--episodes', '1', '--out', {str(out)!r}]\n"
        "entry.main()\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert result.returncode == 130, result.stderr
    assert "Traceback" not in result.stderr and not out.exists()


def test_a_stop_inside_a_compiled_kernel_call_is_a_keyboard_interrupt():
    """numba's dispatcher turns a KeyboardInterrupt raised by the signal handler during a call into
    SystemErrors ("returned a result with an exception set") caused by it: `Kernel` raises the
    KeyboardInterrupt, so the episode loops stop and keep what is finished; other errors pass."""
    from common.compiled import Kernel

    def doubled(x: float) -> float:
        return 2 * x

    kernel = Kernel(doubled)
    assert kernel(2.0) == 4.0 and kernel.__name__ == "doubled"

    def interrupted(*args: object) -> None:
        try:
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as stop:
                raise SystemError(
                    "<function _numba_unpickle> returned a result with an exception set"
                ) from stop
        except SystemError as unpickling:
            raise SystemError("CPUDispatcher returned a result with an exception set") from unpickling

    kernel.compiled = interrupted
    with pytest.raises(KeyboardInterrupt):
        kernel(1.0)

    def broken(*args: object) -> None:
        raise SystemError("something else")

    kernel.compiled = broken
    with pytest.raises(SystemError, match="something else"):
        kernel(1.0)
