"""Hostile inputs and limits (issue 36, defects 10-13): damaged journals, full disks, unbounded
or mistyped values, options without effect, odd destinations. Each ends in one line (exit 2)
before any work, or with the damaged part dropped and said."""

import json
import typing
from pathlib import Path

import annotated_types
import numpy as np
import pytest
from pydantic import BaseModel
from typer.testing import CliRunner

from planner import model_file
from stack.apps.cli import app
from stack.settings.run import RunConfig
from stack.settings.train import TrainConfig
from stack.settings.world import HighwayConfig
from tests.test_cli import tiny_config_file
from tests.test_hostile_inputs import one_line_refusal


def interrupted_run(tmp_path: Path, episodes: int = 2) -> tuple[Path, list[str], Path]:
    """A finished one-episode run turned into an interrupted one (its journal put back)."""
    out = tmp_path / "run"
    arguments = [
        "run",
        "-c",
        str(tiny_config_file(tmp_path)),
        "--agent",
        "keep-lane",
        "--episodes",
        str(episodes),
    ]
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    timings = csv_rows(out / "timings.csv")
    rows = [
        json.dumps(row | timing) for row, timing in zip(csv_rows(out / "episodes.csv"), timings, strict=True)
    ]
    journal = out / "keep-lane.episodes.partial.jsonl"
    journal.write_text(rows[0] + "\n")
    return out, arguments, journal


def csv_rows(path: Path) -> list[dict]:
    """episodes.csv as the typed rows the journal holds."""
    import csv

    def typed(value: str) -> object:
        if value in ("True", "False"):
            return value == "True"
        for kind in (int, float):
            try:
                return kind(value)
            except ValueError:
                pass
        return value

    return [{k: typed(v) for k, v in row.items()} for row in csv.DictReader(path.open())]


@pytest.mark.parametrize(
    "damage",
    [b"\xff\xfe not utf-8\n", b'{"episode": 1, "seed": NaN}\n', b"-Infinity\n"],
)
def test_a_damaged_journal_row_is_dropped_with_a_warning_and_the_rows_before_kept(tmp_path, damage):
    out, arguments, journal = interrupted_run(tmp_path)
    first = json.loads(journal.read_text())
    with journal.open("ab") as handle:
        handle.write(damage)
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume", "--no-progress"])
    assert resumed.exit_code == 0, resumed.output
    assert f"warning: {journal}: dropped line 2" in resumed.output
    assert json.loads((out / "summary.json").read_text())["episodes"] == 2
    assert csv_rows(out / "episodes.csv")[0] | csv_rows(out / "timings.csv")[0] == first


def test_journal_values_out_of_range_never_reach_the_summary(tmp_path):
    out, arguments, journal = interrupted_run(tmp_path)
    row = json.loads(journal.read_text())
    bad = [{**row, "mean_speed": float("nan")}, {**row, "lane_changes": -3}, {**row, "peak_lat_jerk": 1e400}]
    journal.write_text("".join(json.dumps(r) + "\n" for r in bad))
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume", "--no-progress"])
    assert resumed.exit_code == 0 and "dropped line 1, 2, 3" in resumed.output, resumed.output
    summary = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert summary["episodes"] == 2


def test_a_failed_model_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    def disk_full(handle, **_: object) -> None:
        handle.write(b"half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", disk_full)
    with pytest.raises(OSError):
        model_file.save_model(tmp_path / "checkpoint.npz", {"a": np.zeros(3)}, {"kind": "checkpoint"})
    assert list(tmp_path.iterdir()) == []


def numeric_fields(model: type[BaseModel], prefix: str = "") -> typing.Iterator[tuple[str, object]]:
    """(dotted key, field) of every single number of `model` and its sections (pairs such as
    speed ranges are bounded by their validators)."""
    for name, field in model.model_fields.items():
        if typing.get_origin(field.annotation) in (tuple, dict):
            continue
        kinds = typing.get_args(field.annotation) or (field.annotation,)
        for kind in kinds:
            if isinstance(kind, type) and issubclass(kind, BaseModel):
                yield from numeric_fields(kind, f"{prefix}{name}.")
        if int in kinds or float in kinds:
            yield f"{prefix}{name}", field


BOUNDED_BY_VALIDATOR = {"perception.sensor.range_m"}
"""Numbers whose range a validator checks (the sensor range: finite up to 10 km, or .inf)."""


@pytest.mark.parametrize("section", [HighwayConfig, TrainConfig, RunConfig])
def test_every_number_of_every_section_is_bounded_on_both_sides(section):
    def bounded(field: object, kinds: tuple) -> bool:
        metadata = field.metadata  # type: ignore[attr-defined]
        return any(isinstance(m, kinds) for m in metadata)

    unbounded = [
        key
        for key, field in numeric_fields(section)
        if key not in BOUNDED_BY_VALIDATOR
        and not (
            bounded(field, annotated_types.Le | annotated_types.Lt)
            and bounded(field, annotated_types.Ge | annotated_types.Gt)
        )
    ]
    assert unbounded == []


@pytest.mark.parametrize(
    ("setting", "expected"),
    [
        ("highway.ego_spacing=1e308", "--set highway.ego_spacing: highway.ego_spacing: Input should be less"),
        ("highway.lanes_count=true", "--set highway.lanes_count: highway.lanes_count: expected a number"),
        ("highway.vehicles_count=yes", "expected a number, got a boolean (true)"),
        ("perception.control_on_ground_truth=1", "expected true or false, got a number (1)"),
        ("control_rate_hz=20", "--set control_rate_hz: control_rate_hz: must equal"),
        ("train.validation.seed=10000000000000000000000", "train.validation.seed: Input should be less"),
        ("controller.pid.kp_lateral=1e308", "controller.pid.kp_lateral: Input should be less than or equal"),
        ("controller.mpc.weight_lateral=.nan", "controller.mpc.weight_lateral: Input should be a finite"),
        ("controller.lane_change_duration_s=1e-300", "controller.lane_change_duration_s: Input should be"),
        ("controller.lqr.speed_step=1e-9", "controller.lqr.speed_step: Input should be greater than or"),
        ("controller.time_gap_s=1e308", "controller.time_gap_s: Input should be less than or equal to 10"),
        ("planner.safety.min_gap_m=1e308", "planner.safety.min_gap_m: Input should be less than or equal"),
        ("planner.safety.min_ttc_s=.inf", "planner.safety.min_ttc_s: Input should be a finite number"),
        ("planner.oracle.margin_m=-1", "planner.oracle.margin_m: Input should be greater than or equal"),
        ("perception.speed_scale=1e-300", "perception.speed_scale: Input should be greater than or equal"),
        ("perception.ttc_horizon=.inf", "perception.ttc_horizon: Input should be a finite number"),
        ("perception.sensor.range_m=1e308", "perception.sensor.range_m: must be at most 10000 m, or .inf"),
        ("train.scenarios={overtaking: 1e308}", "train.scenarios: scenario 'overtaking': the share must be"),
        (
            "train.reward.speed_range=[true, 30]",
            "train.reward.speed_range.0: expected a number, got a boolean",
        ),
        ("train.scenarios={overtaking: yes}", "train.scenarios.overtaking: expected a number, got a boolean"),
        (
            "highway.traffic={classes: [{name: a, share: on, speed_mps: [20, 30]}]}",
            "--set highway.traffic: highway.traffic.classes.0.share: expected a number, got a boolean",
        ),
    ],
)
def test_mistyped_or_unbounded_values_are_refused_naming_the_option(tmp_path, setting, expected):
    one_line_refusal(["run", "--set", setting, "--out", str(tmp_path / "out")], expected)
    assert not (tmp_path / "out").exists()


def test_an_option_without_effect_is_refused(tmp_path):
    config = str(tiny_config_file(tmp_path))
    one_line_refusal(
        ["run", "-c", config, "--agent", "rule", "--model", "x.npz"], "--model: the rule agent loads no"
    )
    one_line_refusal(
        ["compare", "-c", config, "--agents", "rule,mobil", "--models", "mobil=x.npz"],
        "--models: the mobil agent loads no model file",
    )
    one_line_refusal(
        ["compare", "-c", config, "--agents", "rule", "--models", "ddqn=x.npz"],
        "--models: 'ddqn' is not among",
    )


def test_jobs_beyond_memory_are_refused_before_any_process(tmp_path, monkeypatch):
    from stack.apps import training
    from stack.runtime import executors

    monkeypatch.setattr(training, "available_memory_bytes", lambda: 2 * training.WORKER_BYTES)
    monkeypatch.setattr(executors, "usable_cpus", lambda: 8)
    one_line_refusal(
        ["run", "-c", str(tiny_config_file(tmp_path)), "--jobs", "64", "--out", str(tmp_path / "o")],
        "--jobs: 8 processes need about",
    )
    assert not (tmp_path / "o").exists()


def test_odd_destinations_are_one_line_before_any_work(tmp_path):
    from planner.factory import SHIPPED_MODELS

    long_name = tmp_path / ("x" * 300)
    one_line_refusal(
        ["run", "-c", str(tiny_config_file(tmp_path)), "--out", str(long_name)], "--out: cannot create"
    )
    one_line_refusal(["export", str(SHIPPED_MODELS["ddqn"]), "--sb3", str(long_name)], "File name too long")
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    try:
        if not __import__("os").access(locked, __import__("os").W_OK):
            one_line_refusal(
                ["export", str(SHIPPED_MODELS["ddqn"]), "--sb3", str(locked / "m")], "is not writable"
            )
    finally:
        locked.chmod(0o700)


def test_a_ray_address_where_something_else_listens_is_refused_within_seconds():
    import http.server
    import threading
    import time

    from stack.runtime.ray_tasks import PROBE_TIMEOUT_S, RayUnavailable, check_address

    http_server = http.server.HTTPServer(("127.0.0.1", 0), http.server.BaseHTTPRequestHandler)
    threading.Thread(target=http_server.serve_forever, daemon=True).start()
    silent = __import__("socket").create_server(("127.0.0.1", 0))
    try:
        for port in (http_server.server_address[1], silent.getsockname()[1]):
            started = time.monotonic()
            with pytest.raises(RayUnavailable, match="answers, but not as a Ray cluster"):
                check_address(f"127.0.0.1:{port}")
            assert time.monotonic() - started < PROBE_TIMEOUT_S + 1
    finally:
        http_server.shutdown()
        silent.close()


@pytest.mark.parametrize(
    ("arguments", "expected"),
    [
        (
            ["safety", "--scenario", "lead-braking", "--point", "speed=20,time_gap=1e308,deceleration=4"],
            "time_gap",
        ),
        (
            [
                "safety",
                "--scenario",
                "cut-in",
                "--point",
                "speed=20,relative_speed=1e9,gap=10,lateral_speed=1",
            ],
            "relative_speed",
        ),
        (
            ["safety", "--scenario", "cut-out", "--point", "speed=20,distance=10,lateral_speed=nan"],
            "lateral_speed",
        ),
        (["reproduce", "deepcars", "--quick", "--seed", "-1"], "--seed"),
        (["reproduce", "deepcars", "--quick", "--seed", str(2**40)], "--seed"),
    ],
)
def test_numbers_given_as_options_are_bounded_before_any_work(tmp_path, arguments, expected):
    result = CliRunner().invoke(app, [*arguments, "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and expected in result.output, result.output
    assert "Traceback" not in result.output and not (tmp_path / "out").exists()
