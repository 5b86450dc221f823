"""Issue 52's hostile and careless cases: each one line with the right exit code, nothing written
outside `--out`, nothing finished lost, strict JSON."""

from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.runtime.files import finite, write_json
from tests.test_cli import tiny_config_file
from tests.test_hostile_inputs import one_line_refusal
from tests.test_hostile_limits import interrupted_run

KEEP_LANE = ["--agent", "keep-lane", "--episodes", "1", "--no-progress"]


def strict(text: str) -> object:
    """`text` parsed as strict JSON (NaN and Infinity refused)."""

    def refuse(constant: str) -> None:
        raise ValueError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize(
    "name", [".drivestack.lock", ".summary.partial.json", "keep-lane.episodes.partial.jsonl"]
)
def test_a_link_in_the_folder_never_writes_outside_it(tmp_path, name):
    precious = tmp_path / "precious.txt"
    precious.write_text("keep me\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / name).symlink_to(precious)
    result = CliRunner().invoke(
        app, ["run", "-c", str(tiny_config_file(tmp_path)), *KEEP_LANE, "--out", str(out)]
    )
    assert precious.read_text() == "keep me\n"
    if name == ".drivestack.lock":
        assert result.exit_code == 2 and "is not a plain file" in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    else:
        assert result.exit_code in (0, 2), result.output


def test_a_pipe_as_the_lock_file_is_refused_without_a_hang(tmp_path):
    import os

    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / ".drivestack.lock")
    one_line_refusal(
        ["run", "-c", str(tiny_config_file(tmp_path)), *KEEP_LANE, "--out", str(out)], "is not a plain file"
    )


def test_a_config_integer_of_more_digits_than_python_converts_is_one_line(tmp_path):
    config = tmp_path / "big.yaml"
    config.write_text("seed: " + "9" * 4400 + "\n")
    one_line_refusal(["run", "-c", str(config), "--out", str(tmp_path / "x")], f"{config}: a value it holds")
    assert not (tmp_path / "x").exists()


def test_a_journal_line_with_a_huge_integer_is_dropped_and_the_lines_before_kept(tmp_path):
    out, arguments, journal = interrupted_run(tmp_path, episodes=4)
    with journal.open("a") as handle:
        handle.write('{"episode": ' + "1" * 4400 + "}\n")
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume", "--no-progress"])
    assert resumed.exit_code == 0, resumed.output
    assert f"warning: {journal}: dropped line 2" in resumed.output
    assert json.loads((out / "summary.json").read_text())["episodes"] == 4


def test_results_are_strict_json_with_the_reason_beside_a_non_finite_value(tmp_path):
    data = {"gap": math.inf, "rows": [1.0, -math.inf, math.nan], "inner": {"ttc": math.nan}}
    assert finite(data) == {
        "gap": None,
        "gap_not_finite": "inf",
        "rows": [1.0, None, None],
        "inner": {"ttc": None, "ttc_not_finite": "nan"},
    }
    write_json(tmp_path / "x.json", data)
    assert strict((tmp_path / "x.json").read_text())["gap_not_finite"] == "inf"


def test_the_readmes_cut_in_point_writes_strict_json(tmp_path):
    point = "speed=13.89,relative_speed=6,gap=10,lateral_speed=0.5"
    out = tmp_path / "point"
    result = CliRunner().invoke(app, ["safety", "--scenario", "cut-in", "--point", point, "--out", str(out)])
    assert result.exit_code == 0, result.output
    written = strict((out / "point.json").read_text())
    assert isinstance(written, dict) and written["scenario"] == "cut-in"


@pytest.mark.parametrize("agents", ["", ",,", "mobil,,rule"])
def test_an_empty_agent_list_or_entry_is_one_line(tmp_path, agents):
    one_line_refusal(["compare", "--agents", agents, "--out", str(tmp_path / "x")], "--agents: expected")
    assert not (tmp_path / "x").exists()


def test_an_empty_controller_list_is_one_line(tmp_path):
    one_line_refusal(["track", "--controller", "", "--out", str(tmp_path / "x")], "--controller: expected")


def test_an_empty_set_value_is_refused_and_null_sets_null(tmp_path):
    out = str(tmp_path / "x")
    one_line_refusal(
        ["run", "--set", "highway.duration=4", "--set", "highway.duration=", "--out", out],
        "--set highway.duration: expected a value after '='",
    )
    for null in ("null", "~"):
        one_line_refusal(
            ["run", "--set", f"highway.duration={null}", "--out", out],
            "--set highway.duration: highway.duration: Input should be a valid number (got None)",
        )
    from stack.apps.options import configured

    config = configured(None, ["planner.model=planner/models/ddqn.npz", "planner.model=null"])
    assert config.planner.model is None


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ("perception.features=[ttc,ttc,ttc]", "--set perception.features: perception: features: each"),
        ("hïghway.duration=5", "--set hïghway.duration: hïghway: unknown key"),
        (".".join(["a"] * 60) + "=1", "--set a.a.a.a"),
    ],
)
def test_a_bad_set_blames_the_option_not_the_packaged_config(tmp_path, entry, expected):
    one_line_refusal(["run", "--set", entry, "--out", str(tmp_path / "x")], expected)


def test_a_config_files_own_error_still_blames_the_file_beside_a_set(tmp_path):
    config = tmp_path / "bad.yaml"
    config.write_text("highway: {lanes_count: 0}\n")
    one_line_refusal(
        ["run", "-c", str(config), "--set", "highway.duration=5", "--out", str(tmp_path / "x")],
        f"{config}: highway.lanes_count",
    )


AGENT_RETURNING = """
import numpy as np

class Agent:
    encoding = "paper"
    grid_config = None

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        {body}
"""
CONTROLLER_RETURNING = """
from records import Actuation

class Controller:
    fallbacks = 0

    def __init__(self):
        self.solve_times = []

    def reset(self):
        pass

    def step(self, state, reference):
        return {value}
"""


def cli_line(arguments: list[str], capsys) -> tuple[int, str]:
    """The exit code and stderr of `drivestack ARGUMENTS` through its entry point."""
    from stack.apps.options import guarded

    with pytest.raises(SystemExit) as stopped:
        guarded(app, arguments)
    return int(stopped.value.code or 0), capsys.readouterr().err


def test_a_plugin_that_exits_at_import_is_named_in_one_line(tmp_path):
    plugin = tmp_path / "quits.py"
    plugin.write_text("import sys\nsys.exit(0)\n")
    one_line_refusal(
        ["run", "--agent", f"{plugin}:Agent", "--out", str(tmp_path / "x")],
        "quits.py:Agent: importing it failed: SystemExit: 0",
    )
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("body", "shown"),
    [
        ("raise KeyError('lane')", "predict raised KeyError: 'lane'"),
        ("return 1.5, state", "predict returned 1.5; expected one action index"),
        ("return True, state", "predict returned True; expected one action index"),
        ("return np.array([0, 1, 2]), state", "predict returned array([0, 1, 2]); expected"),
        ("return 7, state", "predict returned 7; expected"),
        ("return 'LEFT', state", "predict returned 'LEFT'; expected"),
    ],
)
def test_a_plugin_agents_bad_predict_is_one_line_naming_it(tmp_path, capsys, body, shown):
    plugin = tmp_path / "bad_agent.py"
    plugin.write_text(AGENT_RETURNING.format(body=body))
    arguments = [
        "run",
        "-c",
        str(tiny_config_file(tmp_path)),
        "--agent",
        f"{plugin}:Agent",
        "--episodes",
        "1",
    ]
    code, err = cli_line([*arguments, "--no-progress", "--out", str(tmp_path / "x")], capsys)
    assert code == 1 and err.startswith(f"error: plug-in {plugin}:Agent: {shown}"), err
    assert len(err.strip().splitlines()) == 1 and "internal error" not in err


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        ("Actuation(acceleration=float('nan'), steering=0.0)", "step returned Actuation(acceleration=nan"),
        ("'full throttle'", "step returned 'full throttle'; expected an Actuation"),
        ("1 / 0", "step raised ZeroDivisionError: division by zero"),
    ],
)
def test_a_plugin_controllers_bad_step_is_one_line_naming_it(tmp_path, capsys, value, shown):
    plugin = tmp_path / "bad_controller.py"
    plugin.write_text(CONTROLLER_RETURNING.format(value=value))
    spec = f"{plugin}:Controller"
    code, err = cli_line(
        ["track", "--controller", spec, "--speeds", "20", "--no-progress", "--out", str(tmp_path / "x")],
        capsys,
    )
    assert code == 1 and err.startswith(f"error: plug-in {spec}: {shown}"), err
    assert not (tmp_path / "x" / "tracking.json").exists()
