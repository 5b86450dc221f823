"""Plug-in agents and controllers: by file and module path in run, compare and track, the same
results over processes, one-line refusals before any episode, entry-point discovery."""

import json
import shutil
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from common import plugins
from stack.apps.cli import app
from stack.results.episode_result import outcome
from tests.test_cli import tiny_config_file

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TINY = ["--set", "highway.duration=3", "--set", "highway.vehicles_count=10", "--no-progress"]


@pytest.fixture
def user_files(tmp_path, monkeypatch):
    """The example plug-ins copied outside the repository, one of them importable as a module."""
    folder = tmp_path / "user"
    folder.mkdir()
    shutil.copy(EXAMPLES / "plugin_agent.py", folder / "my_agent.py")
    shutil.copy(EXAMPLES / "plugin_controller.py", folder / "my_controller.py")
    (folder / "broken.py").write_text("import no_such_package_here\n")
    (folder / "odd.py").write_text("class Odd:\n    encoding = 'paper'\n")
    monkeypatch.syspath_prepend(str(folder))
    yield folder
    for name in ("my_agent", "my_controller"):
        sys.modules.pop(name, None)


def invoke(*arguments: str):
    return CliRunner().invoke(app, list(arguments))


def test_a_file_agent_runs_beside_a_builtin_and_a_module_agent_in_compare(user_files, tmp_path):
    run = invoke(
        "run",
        "--agent",
        f"{user_files}/my_agent.py:LeftWhenBlocked",
        "--beside",
        "keep-lane",
        "--episodes",
        "1",
        "--out",
        str(tmp_path / "run"),
        *TINY,
    )
    assert run.exit_code == 0, run.output
    rows = json.loads((tmp_path / "run" / "beside.json").read_text())
    assert rows[0]["agent"] == f"{user_files}/my_agent.py:LeftWhenBlocked"
    assert "summary: LeftWhenBlocked + pid" in run.output and "\n| LeftWhenBlocked | 1 |" in run.output
    compare = invoke(
        "compare",
        "--agents",
        "my_agent:LeftWhenBlocked,keep-lane",
        "--episodes",
        "1",
        "--out",
        str(tmp_path / "cmp"),
        *TINY,
    )
    assert compare.exit_code == 0, compare.output
    agents = [row["agent"] for row in json.loads((tmp_path / "cmp" / "comparison.json").read_text())]
    assert agents == ["my_agent:LeftWhenBlocked", "keep-lane"]
    assert "\n| LeftWhenBlocked | 1 |" in compare.output


def test_compare_shows_plug_ins_by_class_name_and_names_them_in_full_in_its_files(
    user_files, tmp_path, monkeypatch
):
    """Two files of one name with one class name, the baseline given relative to the working
    directory, a module controller: the figure and the tables tell them apart by the folder, the
    files name them in full."""
    (user_files / "other").mkdir()
    shutil.copy(user_files / "my_agent.py", user_files / "other" / "my_agent.py")
    monkeypatch.chdir(user_files)
    figures = []
    monkeypatch.setattr("stack.apps.compare.save_figure", lambda figure, path, dpi: figures.append(figure))
    agents = ["my_agent.py:LeftWhenBlocked", "other/my_agent.py:LeftWhenBlocked"]
    common = ["--episodes", "1", "--set", "controller.type=my_controller:HeadingPD", *TINY]
    out = tmp_path / "cmp"
    compare = invoke(
        "compare", "--agents", ",".join(agents), "--baseline", agents[0], *common, "--out", str(out)
    )
    assert compare.exit_code == 0, compare.output
    shown = ["user/my_agent.py:LeftWhenBlocked", "other/my_agent.py:LeftWhenBlocked"]
    assert f"speed - {shown[0]} m/s" in compare.output
    assert all(f"\n| {name} | 1 |" in compare.output for name in shown), compare.output
    rows = json.loads((out / "comparison.json").read_text())
    full = [f"{user_files}/{agent}" for agent in agents]
    assert [row["agent"] for row in rows] == full and rows[1]["baseline"] == full[0]
    assert rows[1]["controller"] == "my_controller:HeadingPD" and "difference" in rows[1]
    (figure,) = figures
    figure.canvas.draw()
    for axis in figure.axes:
        assert [tick.get_text() for tick in axis.get_xticklabels()] == shown
    assert "controller HeadingPD" in figure.texts[0].get_text()
    assert shown[0] in figure.axes[-1].get_title()


@pytest.mark.parametrize(
    "names, shown",
    [
        (["/u/a.py:Mine", "mobil"], ["Mine", "mobil"]),
        (["/u/a.py:Mine", "/u/b.py:Mine", "/v/b.py:Mine"], ["a.py:Mine", "u/b.py:Mine", "v/b.py:Mine"]),
        (
            ["pkg.agents:Mine", "other.agents:Mine", "x:Mine"],
            ["pkg.agents:Mine", "other.agents:Mine", "x:Mine"],
        ),
        (["pkg.agents:Mine", "pkg.more:Mine"], ["agents:Mine", "more:Mine"]),
        (["x:rule", "rule"], ["x:rule", "rule"]),
        (["/u/a.py:Mine", "/u/a.py:Mine"], ["Mine", "Mine"]),
    ],
)
def test_short_labels_lengthen_a_class_name_only_as_far_as_it_takes(names, shown):
    assert plugins.short_labels(names) == shown


def test_two_plug_ins_of_one_file_name_keep_apart_journals():
    names = ["/u/agent.py:Mine", "/v/agent.py:Mine", "u.agent:Mine", "mobil"]
    assert len({plugins.file_safe(name) for name in names}) == 4
    assert plugins.file_safe("mobil") == "mobil"


@pytest.mark.slow
def test_a_relative_file_agent_gives_the_same_results_over_two_processes(user_files, tmp_path, monkeypatch):
    monkeypatch.chdir(user_files)
    common = ["compare", "--agents", "my_agent.py:LeftWhenBlocked,rule", "--episodes", "2", *TINY]
    one = invoke(*common, "--jobs", "1", "--out", str(tmp_path / "one"))
    two = invoke(*common, "--jobs", "2", "--out", str(tmp_path / "two"))
    assert one.exit_code == 0 and two.exit_code == 0, two.output
    (first, second) = (
        json.loads((tmp_path / name / "comparison.json").read_text()) for name in ("one", "two")
    )
    assert [outcome(row) for row in first] == [outcome(row) for row in second]
    assert first[0]["agent"] == f"{user_files}/my_agent.py:LeftWhenBlocked"


WORKER_ONLY_FAILURE = """import multiprocessing
import sys

if multiprocessing.current_process().name != "MainProcess" or sys.argv[0].endswith("default_worker.py"):
    raise ImportError("no module named 'lidar_driver' on this worker")

"""


PLUGIN_AGENT, PLUGIN_CONTROLLER = EXAMPLES / "plugin_agent.py", EXAMPLES / "plugin_controller.py"


def fails_on_workers(folder: Path, example: Path = PLUGIN_AGENT, name: str = "LeftWhenBlocked") -> str:
    """The spec of an example plug-in that imports here but raises on a `--jobs` process or a Ray
    worker, as when a library it needs is missing there."""
    path = folder / f"worker_fails_{example.stem}.py"
    path.write_text(WORKER_ONLY_FAILURE + example.read_text())
    return f"{path}:{name}"


def test_a_plug_in_that_a_worker_process_cannot_load_is_one_line(tmp_path):
    """Every plug-in is checked here before any episode; one that still fails where the episodes run
    is one line naming it and why, exit code 2 (was: internal error, exit 1)."""
    out = tmp_path / "out"
    arguments = ["run", "--agent", fails_on_workers(tmp_path), "--episodes", "3", "--jobs", "2"]
    result = invoke(*arguments, *TINY, "--out", str(out))
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: a worker could not load a plug-in"), lines
    assert "LeftWhenBlocked: importing it failed: ImportError: no module named 'lidar_driver'" in lines[0]


def test_a_file_controller_runs_in_run_and_track(user_files, tmp_path):
    spec = f"{user_files}/my_controller.py:HeadingPD"
    run = invoke(
        "run",
        "--agent",
        "keep-lane",
        "--controller",
        spec,
        "--episodes",
        "1",
        "--out",
        str(tmp_path / "run"),
        *TINY,
    )
    assert run.exit_code == 0, run.output
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["controller"] == spec
    track = invoke(
        "track",
        "--controller",
        f"lqr,{spec}",
        "--plant",
        "kinematic",
        "--speeds",
        "20",
        "--out",
        str(tmp_path / "track"),
        "--no-progress",
    )
    assert track.exit_code == 0, track.output
    records = json.loads((tmp_path / "track" / "tracking.json").read_text())
    assert {r["controller"] for r in records} == {"lqr", "my_controller.py:HeadingPD"}


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--agent", "missing.py:A", "missing.py: no such file"),
        ("--agent", "broken.py:A", "broken.py:A: importing it failed: ModuleNotFoundError"),
        ("--agent", "my_agent.py:Nope", "has no class Nope"),
        ("--agent", "odd.py:Odd", "odd.py:Odd: not an agent: attributes encoding"),
        ("--agent", "no_such_module_x:A", "no_such_module_x: no module named no_such_module_x"),
        ("--agent", "not a name", "unknown agent 'not a name'"),
        ("--beside", "odd.py:Odd", "--beside: "),
        ("--controller", "odd.py:Odd", "not a controller: methods reset() and step"),
    ],
)
def test_a_bad_plug_in_is_one_line_and_exit_2_before_any_episode(
    user_files, tmp_path, monkeypatch, option, value, message
):
    monkeypatch.chdir(user_files)
    out = tmp_path / "out"
    result = invoke("run", "-c", str(tiny_config_file(tmp_path)), option, value, "--out", str(out))
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {option}: ") and message in lines[0], lines
    assert not (out / "episodes.csv").exists()


def test_entry_points_add_names_to_the_listings_and_the_configs(user_files, monkeypatch):
    class Point:
        def __init__(self, name, value):
            self.name, self.value = name, value

    installed = {
        plugins.AGENT_GROUP: [Point("leftie", "my_agent:LeftWhenBlocked")],
        plugins.CONTROLLER_GROUP: [Point("heading-pd", "my_controller:HeadingPD")],
    }
    monkeypatch.setattr("importlib.metadata.entry_points", lambda group: installed.get(group, []))
    assert "leftie     installed plug-in my_agent:LeftWhenBlocked" in invoke("agents").output
    assert "heading-pd" in invoke("controllers").output
    from controllers.config import ControllerConfig
    from controllers.tracker import make_controller
    from stack.runs.kept import build_agent
    from stack.settings.run import build_config

    config = build_config({"planner": {"agent": "leftie"}, "controller": {"type": "heading-pd"}})
    assert type(build_agent(config, 0).agent).__name__ == "LeftWhenBlocked"
    controller = make_controller(ControllerConfig(type="heading-pd"), 1 / 15)
    assert type(controller.controller).__name__ == "HeadingPD"
    from stack.apps.track import controller_names

    assert controller_names("all")[-2:] == ["builtin", "heading-pd"]
