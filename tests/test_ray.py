"""`--ray` and `drivestack sweep` on a local 2-CPU Ray instance: the same summaries as `--jobs 1`,
plug-ins from outside the repository as with `--jobs 2`, a sweep that picks its planted best trial,
and bad input (no Ray, an unreachable address, a bad sweep file) as one line with exit code 2
before any work."""

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.apps.options import bare_ray_as_local
from stack.results.episode_result import outcome
from stack.runtime import interrupts, ray_tasks
from stack.runtime.ray_tasks import connect, import_path, worker_call
from tests.test_plugins import PLUGIN_CONTROLLER, fails_on_workers
from tests.test_train import TINY

ray = pytest.importorskip("ray")

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

TINY_RUN = ["--set", "highway.duration=4", "--set", "highway.vehicles_count=10", "--no-progress"]
TINY_TRAINING = {
    **TINY,
    "planner": {"agent": "ddqn"},
    "train": {**TINY["train"], "reward": {"collision": 0.0}},
}
PLANTED_BEST = 20.0
"""The alive reward of the trial that must win: with no crash penalty a return is alive x the
seconds survived, so 20 beats 1, 1.5 and 2 on any episode that lasts a decision."""


def invoke(*arguments: str):
    return CliRunner().invoke(app, list(arguments))


def episode_rows(path) -> list[dict]:
    """The episodes of a results folder's episodes.csv without their timing fields."""
    with path.open() as handle:
        return [outcome(row) for row in csv.DictReader(handle)]


def sweep_file(tmp_path, space: dict, **extra) -> str:
    """A sweep over `space` of trials of 20 steps: a short validation promoted to a long one at
    step 10, a long one at 20."""
    base = {**TINY_TRAINING, "train": {**TINY_TRAINING["train"], "steps": 20}}
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"config": "base.yaml", "space": space, **extra}))
    return str(path)


def test_compare_on_ray_gives_the_summaries_of_one_job(tmp_path, local_ray):
    common = ["compare", "--agents", "rule,keep-lane", "--episodes", "3", *TINY_RUN]
    local = invoke(*common, "--jobs", "1", "--out", str(tmp_path / "local"))
    remote = invoke(*common, "--ray", "local", "--out", str(tmp_path / "ray"))
    assert local.exit_code == 0 and remote.exit_code == 0, remote.output
    rows = [json.loads((tmp_path / name / "comparison.json").read_text()) for name in ("local", "ray")]
    assert [outcome(row) for row in rows[0]] == [outcome(row) for row in rows[1]]


def test_ray_tasks_write_their_episodes_recordings_into_the_folder(tmp_path, local_ray):
    pytest.importorskip("rerun", reason="rerun-sdk (the viz extra) is not installed")
    common = ["run", "--agent", "rule", "--episodes", "2", *TINY_RUN]
    local = invoke(*common, "--out", str(tmp_path / "local"))
    remote = invoke(*common, "--ray", "local", "--record", "--out", str(tmp_path / "ray"))
    assert local.exit_code == 0 and remote.exit_code == 0, remote.output
    assert episode_rows(tmp_path / "local" / "episodes.csv") == episode_rows(
        tmp_path / "ray" / "episodes.csv"
    )
    names = sorted(path.name for path in (tmp_path / "ray" / "recordings").iterdir())
    assert names == ["episode-0000.rrd", "episode-0001.rrd"]


@pytest.mark.slow
def test_plug_ins_from_outside_the_repository_give_the_same_results_on_ray(tmp_path, local_ray, monkeypatch):
    """An agent in a file and a controller as a module, both in a folder outside the repository
    that only this process has on its import path (not the working directory nor PYTHONPATH the
    Ray workers get), the agent beside a built-in: the same episodes with `--jobs 2` and `--ray`."""
    folder = tmp_path / "user"
    folder.mkdir()
    shutil.copy(EXAMPLES / "plugin_agent.py", folder / "file_agent.py")
    shutil.copy(EXAMPLES / "plugin_controller.py", folder / "ray_user_controller.py")
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.delitem(sys.modules, "ray_user_controller", raising=False)
    agents = f"{folder}/file_agent.py:LeftWhenBlocked,mobil"
    controller = ["--set", "controller.type=ray_user_controller:HeadingPD"]
    common = ["compare", "--agents", agents, *controller, "--episodes", "2", *TINY_RUN]
    jobs = invoke(*common, "--jobs", "2", "--out", str(tmp_path / "jobs"))
    remote = invoke(*common, "--ray", "local", "--out", str(tmp_path / "ray"))
    assert jobs.exit_code == 0 and remote.exit_code == 0, remote.output
    rows = [json.loads((tmp_path / name / "comparison.json").read_text()) for name in ("jobs", "ray")]
    assert [outcome(row) for row in rows[0]] == [outcome(row) for row in rows[1]]
    assert [row["agent"] for row in rows[1]] == agents.split(",")
    assert {row["controller"] for row in rows[1]} == {"ray_user_controller:HeadingPD"}
    episodes = [episode_rows(tmp_path / name / "episodes.csv") for name in ("jobs", "ray")]
    assert episodes[0] == episodes[1] and len(episodes[0]) == 4

    single = ["run", "--agent", "mobil", "--controller", "ray_user_controller:HeadingPD", "--episodes", "2"]
    run = invoke(*single, *TINY_RUN, "--ray", "local", "--out", str(tmp_path / "run"))
    assert run.exit_code == 0, run.output
    mobil = [{k: v for k, v in row.items() if k != "agent"} for row in episodes[0][2:]]
    assert episode_rows(tmp_path / "run" / "episodes.csv") == mobil


def test_a_plug_in_that_a_ray_worker_cannot_load_is_one_line(tmp_path, local_ray):
    """A plug-in checked here that raises on the Ray workers: the plug-in's one-line error, exit code
    2, instead of the worker's traceback in a RayTaskError (exit 1)."""
    arguments = ["run", "--agent", fails_on_workers(tmp_path), "--episodes", "2", *TINY_RUN]
    result = invoke(*arguments, "--ray", "local", "--out", str(tmp_path / "out"))
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: a worker could not load a plug-in"), lines
    assert "LeftWhenBlocked: importing it failed: ImportError: no module named 'lidar_driver'" in lines[0]


@pytest.mark.slow
def test_a_plug_in_controller_no_ray_worker_can_load_ends_compare_in_one_line(tmp_path):
    """The command line as a user runs it (its own local Ray instance): every episode's task fails,
    the first is the one line on stderr; Ray prints nothing of the others (its unhandled errors)."""
    controller = fails_on_workers(tmp_path, PLUGIN_CONTROLLER, "HeadingPD")
    arguments = ["compare", "--agents", "keep-lane,mobil", "--set", f"controller.type={controller}"]
    done = subprocess.run(
        [sys.executable, "-m", "stack", *arguments, "--episodes", "2", *TINY_RUN, "--ray", "local"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env={name: value for name, value in os.environ.items() if name not in ray_tasks.QUIET},
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("error: a worker could not load a plug-in") and done.stderr.count("\n") == 1
    assert "HeadingPD: importing it failed: ImportError: no module named 'lidar_driver'" in done.stderr


def test_a_stop_while_ray_starts_waits_for_the_start_then_stops_the_command(monkeypatch, own_handlers):
    """A SIGTERM while `ray.init` runs meets the command's handler, not the one Ray installs (an exit
    wherever the signal finds it, whose half-started core worker then crashed the exit): the stop
    waits for the start, then ends the command like any stop (KeyboardInterrupt)."""
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray_tasks, "watch_descendants", lambda: None)
    started = []

    def stopped_while_starting(**_):
        ray._private.utils.set_sigterm_handler(lambda *_: sys.exit(15))  # as ray.init does
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.1)
        started.append(True)

    monkeypatch.setattr(ray, "init", stopped_while_starting)
    interrupts.catch_signals()
    with pytest.raises(KeyboardInterrupt):
        connect("local")
    assert started == [True] and interrupts.received()
    assert signal.getsignal(signal.SIGTERM) is interrupts._handler


def test_a_ray_task_appends_the_import_path_entries_its_worker_lacks(monkeypatch):
    monkeypatch.setattr(sys, "path", ["/worker/own", "/shared"])
    seen = worker_call(lambda item: (item, list(sys.path)), 7, ["/driver/first", "/shared", "/driver/last"])
    assert seen == (7, ["/worker/own", "/shared", "/driver/first", "/driver/last"])
    monkeypatch.setattr(sys, "path", ["", "relative"])
    assert import_path() == [str(Path.cwd()), str(Path.cwd() / "relative")]


def test_track_on_ray_keeps_the_maneuver_order(tmp_path, local_ray):
    common = ["track", "--controller", "pid", "--plant", "kinematic", "--speeds", "20", "--no-progress"]
    assert invoke(*common, "--out", str(tmp_path / "local")).exit_code == 0
    assert invoke(*common, "--ray", "local", "--out", str(tmp_path / "ray")).exit_code == 0

    def figures(name):
        records = json.loads((tmp_path / name / "tracking.json").read_text())
        return [{k: v for k, v in r.items() if not k.startswith("solve_ms")} for r in records]

    assert figures("local") == figures("ray")


@pytest.mark.slow
def test_sweep_picks_the_planted_best_trial(tmp_path, local_ray):
    spec = sweep_file(tmp_path, {"train.reward.alive": [1.0, 1.5, 2.0, PLANTED_BEST]})
    out = tmp_path / "sweep"
    result = invoke("sweep", "--config", spec, "--out", str(out), "--no-progress")
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["best"]["train.reward.alive"] == PLANTED_BEST and summary["finished"] == 4
    with (out / "trials.csv").open() as handle:
        assert len(list(csv.DictReader(handle))) == 4
    for name in ("best_model.npz", "sweep.png", "trials.md", "config.yaml"):
        assert (out / name).is_file(), name
    trial = next((out / "trials").iterdir())
    assert json.loads((trial / ".drivestack-owner.json").read_text())["command"] == "sweep trial"
    refused = invoke("train", "--resume", str(trial))
    assert refused.exit_code == 2 and "holds the results of `sweep trial`" in refused.output

    resumed = invoke("sweep", "--resume", str(out), "--no-progress")
    assert resumed.exit_code == 0, resumed.output
    again = json.loads((out / "summary.json").read_text())
    assert again["best"] == summary["best"], "resuming a finished sweep trains nothing again"


@pytest.mark.parametrize(
    ("space", "expected"),
    [
        ({"train.learning_rat": [0.001]}, "space: train.learning_rat: unknown key"),
        ({"seed": []}, "space: seed: expected a non-empty list of values"),
        ({"train.gamma": {"uniform": [0.99, 0.9]}}, "train.gamma: uniform: empty range"),
        ({"train.gamma": {"normal": [0.9, 0.1]}}, "train.gamma: expected a list (grid) or one of"),
        ({"train.gamma": [0.9, 2.0]}, "space: train.gamma: Input should be less than or equal to 1"),
    ],
)
def test_a_bad_sweep_file_is_one_line_before_any_trial(tmp_path, space, expected):
    result = invoke("sweep", "--config", sweep_file(tmp_path, space), "--out", str(tmp_path / "out"))
    assert result.exit_code == 2
    assert expected in result.output and len(result.output.strip().splitlines()) == 1, result.output
    assert not (tmp_path / "out").exists()


def test_an_unreachable_address_is_one_line_before_any_episode(tmp_path):
    out = tmp_path / "out"
    result = invoke("run", "--agent", "rule", "--episodes", "1", "--ray", "127.0.0.1:1", "--out", str(out))
    assert result.exit_code == 2
    assert "--ray 127.0.0.1:1: no Ray cluster reachable" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not out.exists()
    nonsense = invoke("run", "--ray", "nowhere", "--out", str(out))
    assert nonsense.exit_code == 2 and "expected local, auto or HOST:PORT" in nonsense.output
    spec = sweep_file(tmp_path, {"seed": [1, 2]})
    sweep = invoke("sweep", "--config", spec, "--ray", "127.0.0.1:1", "--out", str(out))
    assert sweep.exit_code == 2 and "no Ray cluster reachable" in sweep.output and not out.exists()


def test_without_ray_both_paths_say_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    compare = invoke("compare", "--agents", "rule", "--ray", "local", "--out", str(tmp_path / "c"))
    sweep = invoke("sweep", "--config", sweep_file(tmp_path, {"seed": [1, 2]}), "--out", str(tmp_path / "s"))
    for result in (compare, sweep):
        assert result.exit_code == 2
        assert "pip install 'drivestack[ray]'" in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1


def test_the_command_line_imports_ray_only_when_asked():
    probe = "import sys, stack.apps.cli; print('ray' in sys.modules)"
    completed = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert completed.stdout.strip() == "False"


def test_a_bare_ray_option_means_a_local_instance():
    assert bare_ray_as_local(["run", "--ray"]) == ["run", "--ray=local"]
    assert bare_ray_as_local(["run", "--ray", "--jobs", "2"]) == ["run", "--ray=local", "--jobs", "2"]
    assert bare_ray_as_local(["run", "--ray", "auto"]) == ["run", "--ray", "auto"]


def test_a_grpc_server_that_is_not_a_ray_cluster_is_one_line_within_seconds(tmp_path):
    """Issue 52 (17): a proxy or another gRPC service at the address (here a gRPC server with no
    services) used to cost ~20 s of Ray's retries, then a hint about tokens."""
    from concurrent.futures import ThreadPoolExecutor

    import grpc

    server = grpc.server(ThreadPoolExecutor(max_workers=1))
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        out = tmp_path / "out"
        started = time.monotonic()
        result = invoke("run", "--episodes", "1", "--ray", f"127.0.0.1:{port}", "--out", str(out))
        assert time.monotonic() - started < 15, "no minute of retries"
    finally:
        server.stop(None)
    assert result.exit_code == 2, result.output
    assert f"127.0.0.1:{port} answers gRPC, but not as a Ray cluster" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not out.exists()
