import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from stack.apps.cli import app

ROOT = Path(__file__).resolve().parents[1]
SUMMARY_KEYS = {
    "episodes",
    "collisions",
    "collision_rate",
    "accuracy",
    "passed_cars",
    "mean_speed",
    "lane_changes",
    "agent",
    "controller",
    "seed",
}


def tiny_config_file(tmp_path) -> Path:
    data = yaml.safe_load((ROOT / "configs/highway.yaml").read_text())
    data["highway"].update(vehicles_count=10, duration=2)
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def run_tiny(tmp_path, *options: str):
    """`drivestack run` on the tiny config into `tmp_path/out` with `options`: (result, out)."""
    out = tmp_path / "out"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), *options, "--out", str(out), "--no-progress"]
    return CliRunner().invoke(app, arguments), out


def test_run_writes_the_results_folder(tmp_path):
    result, out = run_tiny(tmp_path, "--episodes", "2", "--seed", "4", "--video")
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert (summary["episodes"], summary["seed"], summary["agent"]) == (2, 4, "ddqn")
    rows = (out / "episodes.csv").read_text().strip().splitlines()
    assert len(rows) == 3 and rows[0].startswith("episode,seed,")
    assert (out / "traces.png").stat().st_size > 10_000
    assert (out / "episode0.gif").stat().st_size > 10_000
    assert "collision rate" in result.output


def test_agent_option_swaps_the_agent(tmp_path):
    result, out = run_tiny(tmp_path, "--agent", "keep-lane", "--episodes", "1")
    assert result.exit_code == 0, result.output
    assert json.loads((out / "summary.json").read_text())["agent"] == "keep-lane"


def test_every_learned_agent_drives_out_of_the_box_with_its_shipped_model(tmp_path):
    for agent in ("dqn", "tabular"):
        (tmp_path / agent).mkdir()
        result, out = run_tiny(tmp_path / agent, "--agent", agent, "--episodes", "1", "--scenario", "lanes-5")
        assert result.exit_code == 0, result.output
        summary = json.loads((out / "summary.json").read_text())
        assert summary["agent"] == agent and summary["episodes"] == 1


def test_beside_drives_the_same_seeds_with_a_second_agent_and_prints_both(tmp_path):
    result, out = run_tiny(tmp_path, "--agent", "rule", "--beside", "keep-lane", "--episodes", "2")
    assert result.exit_code == 0, result.output
    rows = json.loads((out / "beside.json").read_text())
    assert [row["agent"] for row in rows] == ["rule", "keep-lane"]
    assert all(row["seed"] == 0 and row["episodes"] == 2 for row in rows)
    assert rows[0]["difference"]["mean_speed"][0] == rows[0]["mean_speed"] - rows[1]["mean_speed"]
    assert json.loads((out / "summary.json").read_text())["agent"] == "rule"
    assert "| speed - keep-lane m/s |" in result.output
    (tmp_path / "b").mkdir()
    bad, elsewhere = run_tiny(tmp_path / "b", "--beside", "genius")
    assert bad.exit_code == 2 and bad.output.startswith("error: --beside: unknown agent 'genius'")
    assert not elsewhere.exists()


def test_bad_input_exits_non_zero_with_one_line(tmp_path):
    result, out = run_tiny(tmp_path, "--agent", "genius")
    assert result.exit_code == 2
    assert "planner.agent: unknown agent 'genius'" in result.output
    assert not out.exists(), "nothing runs or is written before the config validates"


def test_module_entry_point_shows_help():
    completed = subprocess.run(
        [sys.executable, "-m", "stack", "run", "--help"], capture_output=True, text=True, check=True
    )
    assert "--episodes" in completed.stdout


@pytest.mark.parametrize("arguments", [["--help"], ["run", "--help"]])
def test_help_imports_none_of_the_heavy_libraries(arguments):
    """`python -m stack --help` (and `drivestack --help`) answers without numpy, gymnasium, torch or
    highway-env: each command imports what it needs when it runs."""
    probe = (
        "import runpy, sys\n"
        f"sys.argv = ['stack', *{arguments!r}]\n"
        "try:\n"
        "    runpy.run_module('stack', run_name='__main__', alter_sys=True)\n"
        "except SystemExit as stop:\n"
        "    assert not stop.code, stop.code\n"
        "print(sorted({'numpy', 'gymnasium', 'torch', 'highway_env'} & set(sys.modules)))\n"
    )
    completed = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT)
    assert completed.returncode == 0 and "Usage" in completed.stdout, completed.stdout + completed.stderr
    assert completed.stdout.rstrip().endswith("\n[]"), completed.stdout[-200:]


def test_compare_runs_every_agent_on_the_same_episodes(tmp_path):
    out = tmp_path / "cmp"
    result = CliRunner().invoke(
        app,
        [
            "compare",
            "-c",
            str(tiny_config_file(tmp_path)),
            "--agents",
            "rule,keep-lane,random",
            "--baseline",
            "keep-lane",
            "--episodes",
            "2",
            "--out",
            str(out),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    summaries = json.loads((out / "comparison.json").read_text())
    assert [s["agent"] for s in summaries] == ["rule", "keep-lane", "random"]
    assert all(s["episodes"] == 2 and s["seed"] == 0 for s in summaries)
    for s in summaries:
        value, low, high = s["intervals"]["mean_speed"]
        assert value == s["mean_speed"] and low <= value <= high
        assert s["baseline"] == "keep-lane"
    assert summaries[1]["difference"]["mean_speed"] == [0.0, 0.0, 0.0]
    assert "| speed - keep-lane m/s |" in result.output and " [" in result.output
    assert "| longest standstill s / ep |" in result.output
    assert all(len(s["intervals"]["longest_standstill_s"]) == 3 for s in summaries)
    assert (out / "comparison.png").stat().st_size > 5_000
    rows = (out / "episodes.csv").read_text().strip().splitlines()
    assert rows[0].startswith("agent,episode,seed,") and len(rows) == 1 + 3 * 2
    assert [row.split(",")[0] for row in rows[1:]] == [
        "rule",
        "rule",
        "keep-lane",
        "keep-lane",
        "random",
        "random",
    ]
    stray = CliRunner().invoke(app, ["compare", "--agents", "rule", "--baseline", "mobil"])
    assert stray.exit_code == 2 and "--baseline: 'mobil' is not among --agents" in stray.output
    bad = CliRunner().invoke(app, ["compare", "--agents", "rule,genius", "--out", str(tmp_path / "no")])
    assert bad.exit_code == 2 and "unknown agent 'genius'" in bad.output
    assert not (tmp_path / "no").exists()


def test_track_cli_writes_tracking_json_and_plots(tmp_path):
    out = tmp_path / "track"
    result = CliRunner().invoke(
        app, ["track", "--controller", "pid,builtin", "--speeds", "20", "--out", str(out), "--no-progress"]
    )
    assert result.exit_code == 0, result.output
    records = json.loads((out / "tracking.json").read_text())
    assert {r["controller"] for r in records} == {"pid", "builtin"}
    assert {
        "duration_s",
        "overshoot_m",
        "rms_error_m",
        "max_error_m",
        "peak_lat_accel",
        "peak_lat_jerk",
        "solve_ms_p50",
        "solve_ms_p95",
        "fallbacks",
        "speed",
        "direction",
    } <= set(records[0])
    assert (out / "tracking_straight_kinematic_20mps.png").is_file()
    bad = CliRunner().invoke(app, ["track", "--controller", "lqr2", "--out", str(tmp_path / "x")])
    assert bad.exit_code == 2 and "--controller: unknown controller 'lqr2'" in bad.output
    bad = CliRunner().invoke(app, ["track", "--speeds", "fast", "--out", str(tmp_path / "x")])
    assert bad.exit_code == 2 and "--speeds" in bad.output


def test_run_with_the_mpc_controller(tmp_path):
    result, out = run_tiny(tmp_path, "--controller", "mpc", "--episodes", "1")

    assert result.exit_code == 0, result.output
    assert json.loads((out / "summary.json").read_text())["controller"] == "mpc"


def test_a_bad_model_file_fails_before_any_work(tmp_path):
    crafted = tmp_path / "crafted.npz"
    crafted.write_bytes(b"PK\x03\x04 not really a zip")
    result, out = run_tiny(tmp_path, "--agent", "ddqn", "--model", str(crafted))
    assert result.exit_code == 2
    assert f"{crafted}: not a drivestack model file" in result.output.replace("\n", "")
    assert not out.exists()
    missing = CliRunner().invoke(
        app, ["run", "--agent", "dqn", "--model", str(tmp_path / "no.npz"), "--out", str(out)]
    )
    assert missing.exit_code == 2 and "no such model file" in missing.output


def test_the_dynamic_plant_drives_every_command(tmp_path):
    """`--plant dynamic`: the ego is highway-env's dynamic bicycle; its lateral speed and yaw rate
    reach the controllers through the snapshot."""
    result, out = run_tiny(tmp_path, "--plant", "dynamic", "--agent", "keep-lane", "--episodes", "1")
    assert result.exit_code == 0, result.output
    assert json.loads((out / "summary.json").read_text())["plant"] == "dynamic"
    compared = CliRunner().invoke(
        app,
        ["compare", "-c", str(tiny_config_file(tmp_path)), "--agents", "keep-lane", "--plant", "dynamic"]
        + ["--episodes", "1", "--out", str(tmp_path / "cmp"), "--no-progress"],
    )
    assert compared.exit_code == 0, compared.output
    tracked = CliRunner().invoke(
        app,
        ["track", "--controller", "pid,builtin", "--plant", "dynamic", "--speeds", "20"]
        + ["--out", str(tmp_path / "trk"), "--no-progress"],
    )
    assert tracked.exit_code == 0, tracked.output
    records = json.loads((tmp_path / "trk" / "tracking.json").read_text())
    assert {(r["controller"], r["plant"]) for r in records} == {("pid", "dynamic")}
    bad = CliRunner().invoke(app, ["track", "--plant", "rigid", "--out", str(tmp_path / "x")])
    assert bad.exit_code == 2 and "--plant: unknown 'rigid'" in bad.output
    bad, _ = run_tiny(tmp_path, "--plant", "rigid")
    assert (
        bad.exit_code == 2 and "sim.plant: unknown plant 'rigid'; available: kinematic, dynamic" in bad.output
    )


def test_the_snapshot_carries_the_ego_s_body_rates():
    from records import Actuation
    from stack.settings.run import HighwayConfig
    from stack.sim.highway import HighwayAdapter

    for plant in ("kinematic", "dynamic"):
        with HighwayAdapter(HighwayConfig(vehicles_count=5, duration=5), plant=plant) as adapter:
            adapter.reset(seed=0)
            for _ in range(10):
                world = adapter.step(Actuation(acceleration=0.0, steering=0.05))
            ego = world.ego_state()
            assert ego.yaw_rate > 0.1 and ego.lateral_speed != 0.0, plant
            if plant == "kinematic":
                assert abs(ego.yaw_rate - ego.lateral_speed / 2.5) < 1e-12


def test_set_overrides_any_key_and_is_validated_like_the_file(tmp_path):
    result, out = run_tiny(
        tmp_path,
        "--agent",
        "keep-lane",
        "--set",
        "episodes=1",
        "--set",
        "highway.lanes_count=3",
        "--set",
        "seed=9",
    )
    assert result.exit_code == 0, result.output
    written = yaml.safe_load((out / "config.yaml").read_text())
    assert (written["episodes"], written["highway"]["lanes_count"], written["seed"]) == (1, 3, 9)
    for bad, message in [
        ("highway.lanes_count=0", "highway.lanes_count: Input should be greater than or equal to 1"),
        ("highway.wings=2", "highway.wings"),
        ("lanes_count", "--set: expected KEY=VALUE"),
        ("seed=[&a 1, *a]", "--set seed: not a YAML value (anchors and aliases"),
    ]:
        result, _ = run_tiny(tmp_path, "--set", bad)
        assert result.exit_code == 2 and message in result.output, (bad, result.output)
        assert len(result.output.strip().splitlines()) == 1


def test_version_agents_and_the_packaged_defaults_from_any_directory(tmp_path, monkeypatch):
    version = CliRunner().invoke(app, ["--version"])
    assert version.exit_code == 0 and version.output.startswith("drivestack ")
    listing = CliRunner().invoke(app, ["agents"])
    from records import AGENT_NAMES

    lines = listing.output.splitlines()
    assert listing.exit_code == 0 and [line.split()[0] for line in lines[:-1]] == list(AGENT_NAMES)
    assert "or a plug-in: module.path:ClassName" in lines[-1]
    monkeypatch.chdir(tmp_path)  # no configs/ here: the packaged default config runs
    result = CliRunner().invoke(
        app,
        [
            "run",
            "--agent",
            "keep-lane",
            "--set",
            "episodes=1",
            "--set",
            "highway.duration=2",
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    folder = next((tmp_path / "runs").iterdir())
    assert {"summary.json", "config.yaml", "episodes.csv"} <= {p.name for p in folder.iterdir()}


def test_an_error_from_an_option_names_the_option_not_the_file(tmp_path):
    for arguments, message in [
        (["--controller", "nope"], "error: --controller: controller.type: unknown controller 'nope'"),
        (["--scenario", "nope"], "error: --scenario: scenario: unknown scenario 'nope'"),
        (["--set", "seed.x=1"], "error: --set seed.x: seed: not a section"),
    ]:
        result, _ = run_tiny(tmp_path, *arguments)
        assert result.exit_code == 2 and result.output.startswith(message), result.output


def test_run_names_the_model_it_loaded_the_same_one_on_every_scenario(tmp_path):
    for scenario, model in (("lanes-3", "shipped/ddqn.npz"), ("overtaking", "shipped/ddqn.npz")):
        out = tmp_path / scenario
        result = CliRunner().invoke(
            app,
            [
                "run",
                "--scenario",
                scenario,
                "--set",
                "highway.duration=3",
                "--episodes",
                "1",
                "--out",
                str(out),
                "--no-progress",
            ],
        )
        assert result.exit_code == 0, result.output
        assert json.loads((out / "summary.json").read_text())["model"] == model


def test_compare_resume_refuses_a_folder_without_its_comparison_and_an_oversized_journal(tmp_path):
    arguments = ["compare", "-c", str(tiny_config_file(tmp_path)), "--agents", "keep-lane", "--episodes", "2"]
    out = tmp_path / "out"
    for extra, message in (
        ([], "error: --resume: name the folder of the interrupted run with --out"),
        (["--out", str(out)], f"error: --resume: {out} holds no run to resume (no config.yaml)"),
    ):
        result = CliRunner().invoke(app, [*arguments, *extra, "--resume"])
        assert result.exit_code == 2 and result.output.startswith(message), result.output
    assert not out.exists()
    started = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert started.exit_code == 0, started.output
    with (out / "keep-lane.episodes.partial.jsonl").open("wb") as journal:
        journal.truncate(10**12)
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume"])
    assert result.exit_code == 2 and "bytes; a journal of these episodes holds at most 4000" in result.output
    (out / "keep-lane.episodes.partial.jsonl").write_text("[" * 3_000 + "\n" + '{"episode": 0}\n')
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume", "--no-progress"])
    assert result.exit_code == 0 and json.loads((out / "comparison.json").read_text())[0]["episodes"] == 2
