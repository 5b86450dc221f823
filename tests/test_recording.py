"""`--record` and `drivestack view`: recordings read back with rerun's own reader (`rerun.chunk.RrdReader`
and the `rerun rrd verify` command rerun-sdk ships) hold every entity of docs/recording.md, and the
decisions and speeds agree with episodes.csv; results do not change with recording; `view` picks
the worst episode and refuses bad input in one line."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys

import imageio.v2 as imageio
import numpy as np
import pytest
from typer.testing import CliRunner

from stack.apps import view as view_module
from stack.apps.cli import app
from stack.apps.view import viewer_environment, worst_episode
from stack.results.episode_result import outcome
from stack.rrd.recording_file import COLOURS
from tests.test_cli import run_tiny
from tests.test_safety_assessment import NEVER_BRAKES, tiny_grids  # noqa: F401 - a fixture

rerun_chunk = pytest.importorskip("rerun.chunk", reason="rerun-sdk (the viz extra) is not installed")

ENTITIES = {
    "/description",
    "/scene/world",
    "/scene/world/road/lines",
    "/scene/world/road/edges",
    "/scene/world/vehicles/ego",
    "/scene/world/vehicles/leader",
    "/scene/world/vehicles/reacted",
    "/scene/world/vehicles/traffic",
    "/scene/world/reference",
    "/scene/world/grid",
    "/ego/speed",
    "/ego/d",
    "/ego/d_reference",
    "/control/steering",
    "/control/acceleration",
    "/control/lateral_error",
    "/control/heading_error",
    "/control/solve_time",
    "/maneuver/lane",
    "/maneuver/target_lane",
    "/safety/ttc",
    "/safety/below_min_distance",
    "/decision/command",
    "/decision/applied",
    "/decision/scores/LEFT",
    "/decision/scores/STAY",
    "/decision/scores/RIGHT",
    "/events/decisions",
    "/events/maneuver",
}
"""Every entity docs/recording.md lists that each episode has (`/events/safety` only when
something happened)."""


def read(path) -> dict[str, list]:
    """The recording's temporal rows per entity, as (sim_time [s], row of the record batch)."""
    rows: dict[str, list] = {}
    for chunk in rerun_chunk.RrdReader(path).stream():
        table = chunk.to_record_batch().to_pylist()
        entries = rows.setdefault(chunk.entity_path, [])
        for row in table:
            time = row.get("sim_time")
            entries.append((time.total_seconds() if time is not None else None, row))
    for entries in rows.values():
        entries.sort(key=lambda entry: -1.0 if entry[0] is None else entry[0])
    return rows


def values(rows: dict[str, list], entity: str, component: str) -> list:
    """The temporal values of `component` of `entity`, in time order (one per row)."""
    found = []
    for time, row in rows[entity]:
        if time is not None and row.get(component) is not None:
            found.append(row[component][0])
    return found


def test_recorded_episodes_hold_every_entity_and_agree_with_the_results(tmp_path):
    result, out = run_tiny(tmp_path, "--agent", "mobil", "--episodes", "2", "--seed", "5", "--record")
    assert result.exit_code == 0, result.output
    assert f"drivestack view {out} --worst" in result.output.replace("\n", "")
    with (out / "episodes.csv").open() as handle:
        episodes = list(csv.DictReader(handle))
    for episode in episodes:
        path = out / "recordings" / f"episode-{int(episode['episode']):04d}.rrd"
        rows = read(path)
        assert ENTITIES <= set(rows), sorted(ENTITIES - set(rows))
        speeds = values(rows, "/ego/speed", "Scalars:scalars")
        assert np.mean(speeds) == pytest.approx(float(episode["mean_speed"]), abs=1e-9)
        assert len(speeds) == int(episode["steps"]) + 1, "the start and every tick"
        decisions = values(rows, "/events/decisions", "TextLog:text")
        commands = values(rows, "/decision/command", "Scalars:scalars")
        assert len(decisions) == len(commands) > 0
        masked = sum("masked by the safety layer" in text for text in decisions)
        assert masked == int(episode["masked_commands"])
        started = sum(
            "permitted" in text and command != 0 for text, command in zip(decisions, commands, strict=True)
        )
        assert started == int(episode["lane_changes"])
        scores = values(rows, "/decision/scores/STAY", "Scalars:scalars")
        assert scores == [0.0] * len(commands), "MOBIL rates staying 0 m/s² and each change by its gain"
        summary = json.loads((out / "summary.json").read_text())
        assert summary["episodes"] == 2
    verified = subprocess.run(
        [str(view_module.rerun_program()), "rrd", "verify", *map(str, (out / "recordings").glob("*.rrd"))],
        env=viewer_environment(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert verified.returncode == 0, verified.stderr[-2000:]


def results_text(out) -> list[dict[str, str]]:
    """episodes.csv's rows as written (text), without the measured computing times (`outcome`):
    those differ between any two runs, recorded or not."""
    with (out / "episodes.csv").open(newline="") as handle:
        return [outcome(row) for row in csv.DictReader(handle)]


def test_recording_changes_no_result_and_workers_write_their_own_episodes(tmp_path):
    (tmp_path / "plain").mkdir()
    (tmp_path / "recorded").mkdir()
    plain, plain_out = run_tiny(tmp_path / "plain", "--agent", "rule", "--episodes", "3", "--seed", "7")
    recorded, recorded_out = run_tiny(
        tmp_path / "recorded", "--agent", "rule", "--episodes", "3", "--seed", "7", "--record", "--jobs", "2"
    )
    assert plain.exit_code == recorded.exit_code == 0, plain.output + recorded.output
    assert results_text(plain_out) == results_text(recorded_out)
    files = sorted(path.name for path in (recorded_out / "recordings").iterdir())
    assert files == ["episode-0000.rrd", "episode-0001.rrd", "episode-0002.rrd"], "whole files, no .part"


def test_compare_records_each_agent_and_prints_how_to_open_its_worst_episode(tmp_path):
    out = tmp_path / "cmp"
    config = tmp_path / "tiny.yaml"
    run_tiny(tmp_path, "--episodes", "0")  # writes tmp_path/tiny.yaml
    arguments = ["compare", "--agents", "rule,keep-lane", "--episodes", "1", "-c", str(config)]
    result = CliRunner().invoke(app, [*arguments, "--record", "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    for agent in ("rule", "keep-lane"):
        assert (out / "recordings" / agent / "episode-0000.rrd").is_file()
        assert f"drivestack view {out} --worst --agent {agent}" in result.output.replace("\n", "")
    assert worst_episode(out, "keep-lane") == out / "recordings" / "keep-lane" / "episode-0000.rrd"


def test_track_records_each_maneuver(tmp_path):
    out = tmp_path / "track"
    arguments = ["track", "--controller", "pid", "--plant", "kinematic", "--speeds", "20", "--record"]
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    names = sorted(path.name for path in (out / "recordings").glob("*.rrd"))
    assert len(names) == 6 and "pid-straight-kinematic-20mps-left.rrd" in names
    rows = read(out / "recordings" / "pid-straight-kinematic-20mps-left.rrd")
    phases = values(rows, "/events/maneuver", "TextLog:text")
    assert phases[:2] == ["keep lane 1", "change lane 1 -> 0"]


def test_safety_records_only_its_failure_points(tmp_path, tiny_grids):  # noqa: F811 - the fixture
    out = tmp_path / "never"
    arguments = ["safety", "--scenario", "lead-braking", "--quick", *NEVER_BRAKES, "--record"]
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    recordings = list((out / "recordings").glob("*.rrd"))
    assert [path.name for path in recordings] == ["lead-braking-speed-20_time_gap-1_deceleration-3.rrd"]
    assert f"drivestack view {recordings[0]}" in result.output.replace("\n", "")
    events = values(read(recordings[0]), "/events/safety", "TextLog:text")
    assert any(text.startswith("collision: ") for text in events)


def write_results(folder, rows):
    (folder / "recordings").mkdir(parents=True)
    with (folder / "episodes.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    for row in rows:
        (folder / "recordings" / f"episode-{row['episode']:04d}.rrd").write_bytes(b"")


def test_worst_is_a_collision_else_the_slowest_episode(tmp_path):
    rows = [
        {"episode": 0, "crashed": False, "at_fault_collision": False, "mean_speed": 20.0},
        {"episode": 1, "crashed": False, "at_fault_collision": False, "mean_speed": 12.5},
        {"episode": 2, "crashed": False, "at_fault_collision": False, "mean_speed": 25.0},
    ]
    write_results(tmp_path / "slow", rows)
    assert worst_episode(tmp_path / "slow").name == "episode-0001.rrd"
    rows[2] |= {"crashed": True}
    write_results(tmp_path / "crash", rows)
    assert worst_episode(tmp_path / "crash").name == "episode-0002.rrd"


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["nowhere"], "nowhere: no such file or folder"),
        (["RESULTS", "--agent", "rule"], "--agent: chooses whose worst episode --worst opens"),
        (["EMPTY", "--worst"], "no episodes.csv"),
        (["EMPTY"], "holds no recordings"),
        (["RESULTS/episodes.csv"], "expected a rerun recording (.rrd) or a results folder"),
    ],
)
def test_view_refuses_bad_input_in_one_line(tmp_path, arguments, message):
    write_results(tmp_path / "RESULTS", [{"episode": 0, "crashed": False, "mean_speed": 1.0}])
    (tmp_path / "EMPTY").mkdir()
    given = [str(tmp_path / a) if a.isupper() or a.startswith("RESULTS") else a for a in arguments]
    result = CliRunner().invoke(app, ["view", *given])
    assert result.exit_code == 2, result.output
    assert message in result.output and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1


@pytest.mark.parametrize("command", [["run", "--record"], ["view", "x.rrd"], ["track", "--record"]])
def test_without_rerun_record_and_view_say_how_to_install_it(tmp_path, monkeypatch, command):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "rerun" else real(name, *a)
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(app, [*command, "--out", str(out)] if command[0] != "view" else command)
    assert result.exit_code == 2, result.output
    assert "pip install 'drivestack[viz]'" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not out.exists(), "refused before any work"


def test_the_viewer_runs_with_rerun_analytics_off(monkeypatch):
    monkeypatch.setenv("FORCE_RERUN_ANALYTICS", "1")
    environment = viewer_environment()
    assert environment["CI"] == "1" and "FORCE_RERUN_ANALYTICS" not in environment
    assert os.environ["FORCE_RERUN_ANALYTICS"] == "1", "only the viewer's environment changes"


@pytest.mark.slow
def test_view_web_serves_a_viewer_that_draws_the_road_and_the_vehicles(tmp_path):
    """`drivestack view --web` on a recording, opened in headless Chromium (software WebGL): the
    road view shows the road's edges, the ego and the traffic in their colours, not a blank page;
    the viewer leaves no analytics files in its home."""
    from tests.headless_chromium import chromium, screenshot

    if chromium() is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium)")
    result, out = run_tiny(tmp_path, "--episodes", "1", "--seed", "3", "--record")
    assert result.exit_code == 0, result.output
    home = tmp_path / "home"
    home.mkdir()
    environment = {k: v for k, v in os.environ.items() if not k.startswith("XDG_")} | {"HOME": str(home)}
    viewer = subprocess.Popen(
        [sys.executable, "-m", "stack", "view", "--web", str(out / "recordings" / "episode-0000.rrd")],
        env=environment,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        address = None
        assert viewer.stdout is not None
        for line in viewer.stdout:
            if line.startswith("web viewer (this machine only): "):
                address = line.split(": ", 1)[1].strip()
                break
        assert address is not None and address.startswith("http://127.0.0.1:")
        picture = imageio.imread(screenshot(address, tmp_path / "viewer.png", wait_s=30.0))[:, :, :3]
    finally:
        viewer.send_signal(signal.SIGINT)
        viewer.wait(timeout=30)
    height, width = picture.shape[:2]
    road_view = picture[int(0.05 * height) : int(0.6 * height), : int(0.55 * width)].astype(int)

    def pixels(colour: tuple[int, int, int]) -> int:
        return int((np.abs(road_view - np.array(colour)).sum(axis=2) < 40).sum())

    assert pixels(COLOURS["edges"]) > 200, "the road's edges"
    assert pixels(COLOURS["ego"]) > 10, "the ego's box"
    assert pixels(COLOURS["traffic"]) > 50, "the traffic's boxes"
    assert len(np.unique(road_view.reshape(-1, 3), axis=0)) > 20, "not a blank page"
    assert not (home / ".config" / "rerun" / "analytics.json").exists(), "analytics stayed off"
