"""Issue 73's hostile and careless cases: a config that validates runs to its end, nothing coerced
or mixed silently, the Python API as strict as the CLI; each refusal one line with the right exit
code."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from common.plugins import file_safe
from stack.apps.cli import app
from stack.runtime.files import JOURNAL
from tests.test_cli import tiny_config_file
from tests.test_hostile_inputs import one_line_refusal
from tests.test_hostile_limits import csv_rows
from tests.test_plugins import PLUGIN_AGENT

TINY_WORLD = {"highway": {"duration": 2, "vehicles_count": 5}}


def test_a_long_episode_has_a_road_as_long_as_it(tmp_path):
    """highway-env's lanes end 10 km on; past the end traffic loses sight of its leaders, so a
    3600-s episode ended in a collision about 500 s in. The road now outlasts the episode at
    highway-env's top speed, and a default episode keeps highway-env's own road."""
    from highway_env.vehicle.kinematics import Vehicle

    from stack.settings.world import HighwayConfig
    from stack.sim.highway import HighwayAdapter

    for duration, longest in ((40.0, 10_000.0), (3600.0, None)):
        with HighwayAdapter(HighwayConfig(duration=duration, vehicles_count=20)) as adapter:
            world = adapter.reset(seed=3)
            lanes = world.lanes
            needed = float(world.s.max()) + Vehicle.MAX_SPEED * duration
            assert all(lane.length >= needed for lane in lanes)
            if longest is not None:
                assert all(lane.length == longest for lane in lanes)


def test_batched_worlds_drive_the_same_long_road():
    from highway_env.vehicle.kinematics import Vehicle

    from stack.settings.world import HighwayConfig
    from stack.sim.batch.traffic import TrafficBatch

    batch = TrafficBatch(HighwayConfig(duration=3600, vehicles_count=10), worlds=2)
    batch.reset([1, 2])
    assert (batch.arrays.lane_length >= Vehicle.MAX_SPEED * 3600).all()
    batch.close()


def test_every_sweep_trial_keeps_the_fixed_keys_when_the_space_holds_scenarios(tmp_path):
    """A `scenario` param moves the base to that world; the fixed keys still hold for the trial,
    and a fixed null is applied, not dropped."""
    from stack.apps.options import TRAIN_CONFIG
    from stack.apps.sweep import BASE, prepare
    from stack.settings.sweep import load_sweep, trial_config

    fixed = {
        "train.members": 1,
        "train.scenarios": {},
        "train.demonstrations": None,
        "highway.duration": 6,
        "highway.vehicles_count": 12,
    }
    spec = {"config": str(TRAIN_CONFIG), "fixed": fixed, "space": {"scenario": ["dense", "jam"]}}
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(spec))
    sweep, base, _ = load_sweep(tmp_path / "sweep.yaml")
    (folder := tmp_path / "sweep").mkdir()
    prepare(sweep, base, folder)
    stored, _, _ = load_sweep(folder / "sweep.yaml")
    for scenario in ("dense", "jam"):
        trial = trial_config(folder / BASE, stored.fixed, {"scenario": scenario})
        assert (trial.scenario, trial.highway.duration, trial.highway.vehicles_count) == (scenario, 6, 12)
        assert trial.train.scenarios == {} and trial.train.demonstrations is None


def test_a_null_in_a_sweeps_fixed_is_refused_where_null_is_not_allowed(tmp_path):
    from stack.apps.options import TRAIN_CONFIG

    spec = {"config": str(TRAIN_CONFIG), "fixed": {"train.scenarios": None}, "space": {"seed": [1, 2]}}
    (sweep := tmp_path / "sweep.yaml").write_text(yaml.safe_dump(spec))
    expected = f"{sweep}: fixed: train.scenarios: Input should be a valid dictionary"
    one_line_refusal(["sweep", "-c", str(sweep), "--out", str(tmp_path / "s")], expected)


def test_a_relative_model_is_written_as_the_file_it_named(tmp_path, monkeypatch):
    from stack.apps.options import configured
    from stack.apps.resume import resolved_config

    monkeypatch.chdir(tmp_path)
    (tmp_path / "dqn.npz").write_bytes(b"")
    config = configured(None, [], planner__agent="dqn", planner__model="dqn.npz")
    written = yaml.safe_load(resolved_config([config]))
    assert written["planner"]["model"] == str(tmp_path.resolve() / "dqn.npz")


@pytest.mark.parametrize(
    ("actions", "expected"),
    [
        ([1.7, 0.2, 1.0, 2.9], "float64"),
        ([True, False, True, True], "bool"),
        (1, "shape ()"),
        ([1, 1, 1], "shape (3,)"),
        ([1, 1, 1, 5], "commands 0..2"),
        ([-(2**63)] * 4, "commands 0..2"),
    ],
)
def test_the_vector_envs_refuse_actions_they_would_coerce(vector_env, actions, expected):
    for env in vector_env:
        with pytest.raises(ValueError, match="actions: expected") as refused:
            env.step(actions) if hasattr(env, "single_action_space") else env.step(np.asarray(actions))
        assert expected in str(refused.value) and "\n" not in str(refused.value)


@pytest.fixture(scope="module")
def vector_env():
    import gymnasium as gym

    import stack  # noqa: F401  (registers the envs)
    from stack.training.gym_vector_env import DecisionVecEnv

    gymnasium_env = gym.make_vec(
        "drivestack/HierarchicalHighway-v0",
        num_envs=4,
        vectorization_mode="vector_entry_point",
        config=TINY_WORLD,
    )
    gymnasium_env.reset(seed=1)
    sb3_env = DecisionVecEnv(TINY_WORLD, 4, seed=1)
    sb3_env.reset()
    yield gymnasium_env, sb3_env
    gymnasium_env.close()
    sb3_env.close()


@pytest.mark.parametrize("num_envs", [10**6, 1.5, 0, True])
def test_the_vector_envs_refuse_a_world_count_before_allocating(num_envs):
    import gymnasium as gym

    from stack.training.gym_vector_env import DecisionVecEnv

    with pytest.raises(ValueError, match="num_envs: expected a whole number of worlds from 1 to 1024"):
        DecisionVecEnv(TINY_WORLD, num_envs)
    with pytest.raises(ValueError, match="num_envs: expected"):
        gym.make_vec(
            "drivestack/HierarchicalHighway-v0", num_envs=num_envs, vectorization_mode="vector_entry_point"
        )


def test_the_vector_env_says_what_a_seed_should_be_and_hints_sync_only_where_it_helps(vector_env):
    import gymnasium as gym

    gymnasium_env, _ = vector_env
    for seed in (1.5, [1, 2], "x"):
        with pytest.raises(ValueError, match="seed: expected an integer, None or one integer"):
            gymnasium_env.reset(seed=seed)
    with pytest.raises(ValueError) as refused:
        gym.make_vec(
            "drivestack/HierarchicalHighway-v0",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            config={"highway": {"duration": -3}},
        )
    assert "highway.duration" in str(refused.value) and "vectorization_mode" not in str(refused.value)


@pytest.mark.slow
def test_resume_after_the_plug_in_file_was_edited_is_refused_naming_it(tmp_path):
    agent = tmp_path / "agent.py"
    agent.write_text(PLUGIN_AGENT.read_text())
    out = tmp_path / "run"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), "--agent", f"{agent}:LeftWhenBlocked"]
    arguments += ["--episodes", "2", "--out", str(out), "--no-progress"]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    first = json.dumps(csv_rows(out / "episodes.csv")[0] | csv_rows(out / "timings.csv")[0])
    journal = out / f"{file_safe(f'{agent.resolve()}:LeftWhenBlocked')}.{JOURNAL}"
    agent.write_text(agent.read_text() + "\n# edited\n")
    journal.write_text(first + "\n")
    one_line_refusal([*arguments, "--resume"], f"{agent} was edited since the run")


def test_resume_after_a_module_plug_in_was_edited_is_refused_naming_its_file(tmp_path, monkeypatch):
    package = tmp_path / "site"
    package.mkdir()
    agent = package / "edited_agent.py"
    agent.write_text(PLUGIN_AGENT.read_text())
    monkeypatch.syspath_prepend(str(package))
    out = tmp_path / "run"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), "--agent", "edited_agent:LeftWhenBlocked"]
    arguments += ["--episodes", "2", "--out", str(out), "--no-progress"]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    assert f"{agent} sha256" in (out / "config.yaml").read_text()
    first = json.dumps(csv_rows(out / "episodes.csv")[0] | csv_rows(out / "timings.csv")[0])
    journal = out / f"{file_safe('edited_agent:LeftWhenBlocked')}.{JOURNAL}"
    agent.write_text(agent.read_text() + "\n# edited\n")
    journal.write_text(first + "\n")
    one_line_refusal([*arguments, "--resume"], f"{agent} was edited since the run")


def test_track_again_after_the_controller_plug_in_was_edited_says_which(tmp_path):
    """`track` keeps no maneuver of an earlier run (it has no --resume: the same command in its own
    folder measures every maneuver again); its config.yaml records each controller plug-in's digest,
    and a restart after one was edited says which file, as `run --resume` does (`edited_file`)."""
    from tests.test_plugins import PLUGIN_CONTROLLER

    controller = tmp_path / "controller.py"
    controller.write_text(PLUGIN_CONTROLLER.read_text())
    arguments = ["track", "--controller", f"pid,{controller}:HeadingPD", "--plant", "kinematic"]
    arguments += ["--speeds", "20", "--out", str(out := tmp_path / "track"), "--no-progress"]
    first = CliRunner().invoke(app, arguments)
    assert first.exit_code == 0 and "warning" not in first.output, first.output
    assert f"{controller} sha256" in (out / "config.yaml").read_text()
    controller.write_text(controller.read_text() + "\n# edited\n")
    again = CliRunner().invoke(app, arguments)
    assert again.exit_code == 0, again.output
    warning = f"warning: {controller} was edited since the maneuvers in this folder were measured"
    assert again.output.count(warning) == 1, again.output
    records = json.loads((out / "tracking.json").read_text())
    assert {r["controller"] for r in records} == {"pid", "controller.py:HeadingPD"}


@pytest.mark.parametrize(
    ("metadata", "expected"),
    [
        ({"trained_steps": -5}, "trained_steps: expected an integer, at least 0"),
        ({"seed": "7"}, "seed: expected an integer"),
        ({"seed": -1}, "seed: expected an integer"),
    ],
)
def test_ensemble_refuses_crafted_member_metadata(tmp_path, metadata, expected):
    from planner.factory import SHIPPED_MODELS
    from planner.model_file import load_model, save_model

    arrays, stored = load_model(SHIPPED_MODELS["ddqn"])
    save_model(crafted := tmp_path / "crafted.npz", arrays, {**stored, **metadata})
    arguments = ["ensemble", str(SHIPPED_MODELS["ddqn"]), str(crafted), "--out", str(tmp_path / "e.npz")]
    one_line_refusal(arguments, expected)


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ("highway={duration: 3, duration: 5}", "key 'duration' given twice"),
        ("highway.duration=&a 4", "anchors and aliases (&, *) are not accepted"),
        ("seed=" + "[" * 500 + "]" * 500, "nested more than 64 deep"),
    ],
)
def test_a_set_value_with_a_duplicate_key_an_anchor_or_deep_nesting_is_one_line(tmp_path, entry, expected):
    one_line_refusal(["run", "--agent", "keep-lane", "--set", entry, "--out", str(tmp_path / "x")], expected)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("content", "expected"),
    [("seed: 1\nseed: 2\n", "key 'seed' given twice"), ("seed: " + "[" * 500 + "]" * 500, "nested more")],
)
@pytest.mark.parametrize("command", ["run", "sweep"])
def test_a_config_with_a_duplicate_key_or_deep_nesting_is_one_line(tmp_path, content, expected, command):
    (config := tmp_path / "c.yaml").write_text(content)
    one_line_refusal([command, "-c", str(config), "--out", str(tmp_path / "x")], f"{config}: not valid YAML")


def test_a_point_naming_a_parameter_twice_is_refused(tmp_path):
    point = "speed=20,speed=30,time_gap=1,deceleration=4"
    arguments = ["safety", "--scenario", "lead-braking", "--point", point, "--out", str(tmp_path / "s")]
    one_line_refusal(arguments, "--point: speed: given twice")


def test_an_owner_record_nested_deep_is_an_unknown_owner(tmp_path):
    from stack.runtime.owner import MARKER, owner_of

    (tmp_path / MARKER).write_text("[" * 100_000 + "]" * 100_000)
    assert owner_of(tmp_path).command == "unknown command"


QUITTER = """
import sys


class Agent:
    encoding = "paper"
    grid_config = None

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        sys.exit(0)


class Controller:
    fallbacks = 0
    solve_times: list = []

    def reset(self):
        pass

    def step(self, state, reference):
        sys.exit(0)
"""


@pytest.mark.parametrize(
    "arguments",
    [
        ["run", "--agent", "{file}:Agent", "--episodes", "1"],
        ["run", "--controller", "{file}:Controller", "--episodes", "1"],
        ["compare", "--agents", "{file}:Agent,keep-lane", "--episodes", "2", "--jobs", "2"],
    ],
)
def test_a_plug_in_that_exits_while_running_is_one_line_and_exit_1(tmp_path, arguments, capsys):
    from stack.apps.options import guarded

    (quitter := tmp_path / "quitter.py").write_text(QUITTER)
    filled = [argument.replace("{file}", str(quitter)) for argument in arguments]
    config = ["-c", str(tiny_config_file(tmp_path)), "--out", str(tmp_path / "out"), "--no-progress"]
    with pytest.raises(SystemExit) as stopped:
        guarded(app, [*filled, *config])
    output = capsys.readouterr()
    assert stopped.value.code == 1, output
    assert "raised SystemExit: 0" in output.err and str(quitter) in output.err
    assert len(output.err.strip().splitlines()) == 1 and not output.out


def finished_run(tmp_path, *options: str):
    """A finished 2-episode keep-lane run with `options`, turned into an interrupted one."""
    out = tmp_path / "run"
    arguments = ["run", "-c", str(tiny_config_file(tmp_path)), "--agent", "keep-lane", "--episodes", "2"]
    arguments += [*options, "--out", str(out), "--no-progress"]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    first = json.dumps(csv_rows(out / "episodes.csv")[0] | csv_rows(out / "timings.csv")[0])
    (out / f"keep-lane.{JOURNAL}").write_text(first + "\n")
    return out, [*arguments, "--resume"]


def test_a_sub_folder_replaced_by_a_link_is_refused_before_anything_is_written_through_it(tmp_path):
    out, resume = finished_run(tmp_path, "--record")
    elsewhere = tmp_path / "elsewhere"
    (out / "recordings").rename(elsewhere)
    (out / "recordings").symlink_to(elsewhere)
    before = {path.name: path.read_bytes() for path in elsewhere.iterdir()}
    one_line_refusal(resume, f"{out / 'recordings'} is a link; a results folder holds no links")
    assert {path.name: path.read_bytes() for path in elsewhere.iterdir()} == before


def test_a_link_deep_in_a_training_folder_is_refused_on_resume(tmp_path):
    from tests.test_hostile_inputs import owned_training_folder

    folder = tmp_path / "run"
    owned_training_folder(folder, {"train": {"steps": 10}, "highway": {"duration": 2}})
    (folder / "seed-1").mkdir()
    (folder / "seed-1" / "tensorboard").symlink_to(tmp_path)
    one_line_refusal(["train", "--resume", str(folder), "--no-progress"], "tensorboard is a link")


def test_a_plain_file_where_recordings_go_is_one_line_on_resume(tmp_path):
    out, resume = finished_run(tmp_path, "--record")
    shutil.rmtree(out / "recordings")
    (out / "recordings").write_text("not a folder\n")
    result = CliRunner().invoke(app, resume)
    assert result.exit_code == 2, result.output
    assert (
        f"cannot write {out / 'recordings'} (something that is not a folder is in its place)" in result.output
    )


def test_train_refuses_more_env_processes_than_cpus_before_any(tmp_path, monkeypatch):
    monkeypatch.setattr("stack.runtime.machine.usable_cpus", lambda: 2)
    arguments = ["train", "--envs", "64", "--steps", "10", "--out", str(tmp_path / "t")]
    one_line_refusal(arguments, "train.envs: 64 processes step one CPU each, but this machine has 2")
    assert not (tmp_path / "t").exists()


def test_a_checkpoint_declaring_more_than_the_run_can_hold_is_refused_before_inflating(tmp_path):
    import tracemalloc

    from tests.test_hostile_inputs import owned_training_folder
    from tests.test_model_files import metadata_bytes, npy, write

    folder = tmp_path / "run"
    owned_training_folder(folder, {"train": {"steps": 10, "buffer_size": 1000}, "highway": {"duration": 2}})
    zeros = npy(np.zeros(40 * 2**20, dtype=np.float64))  # 320 MB inflated, 0.3 MB packed
    counters = {"format": "drivestack-model/1", "kind": "checkpoint", "counters": {"num_timesteps": 5}}
    write(folder / "checkpoint.npz", {"metadata.npy": metadata_bytes(counters), "array/buffer/x.npy": zeros})
    tracemalloc.start()
    one_line_refusal(["train", "--resume", str(folder), "--no-progress"], "MB when unpacked; at most")
    assert tracemalloc.get_traced_memory()[1] < 100 * 2**20
    tracemalloc.stop()


def oversized_buffer_checkpoint(shape: tuple[int, ...], fields: tuple[str, ...]) -> bytes:
    """A checkpoint whose replay-buffer `fields` each hold zeros (float32) of `shape` (rows, envs,
    observation), as their `.npy` headers truthfully declare: 4 bytes a value inflated, about a
    thousandth of it packed."""
    import io
    import zipfile

    from tests.test_model_files import metadata_bytes, npy

    counters = {"format": "drivestack-model/1", "kind": "checkpoint", "counters": {"num_timesteps": 5}}
    zeros = npy(np.zeros(shape, dtype=np.float32))
    packed = io.BytesIO()
    with zipfile.ZipFile(packed, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("metadata.npy", metadata_bytes(counters))
        for field in fields:
            archive.writestr(f"array/buffer/{field}.npy", zeros)
    return packed.getvalue()


def test_a_checkpoint_whose_headers_do_not_fit_the_run_is_refused_from_them(tmp_path):
    """Within the run's own size bound (257 MB for 1,000 transitions), a buffer of 200 MB
    inflated was read whole before the restore refused it; its header already says it holds more
    rows than the run's buffer, and an array the run's checkpoint never holds is refused too."""
    import tracemalloc

    from stack.settings.run import build_config
    from stack.training.checks import checkpoint_bytes, transition_bytes
    from tests.test_hostile_inputs import owned_training_folder

    folder = tmp_path / "run"
    config = {"train": {"steps": 10, "buffer_size": 1000}, "highway": {"duration": 2}}
    owned_training_folder(folder, config)
    size = (transition_bytes(build_config(config)) - 20) // 8
    rows = 200 * 2**20 // (4 * size)
    crafted = oversized_buffer_checkpoint((rows, 1, size), ("observations",))
    assert rows * size * 4 < checkpoint_bytes(build_config(config)) and len(crafted) < 2**20
    (folder / "checkpoint.npz").write_bytes(crafted)
    arguments = ["train", "--resume", str(folder), "--no-progress"]
    import torch._dynamo  # noqa: F401  the model's optimizer imports it when first built: traced, ~10x slower

    import stack.apps.members  # noqa: F401  the trainer's imports (torch, ...) traced would count ~130 MB
    import stack.training.trainer  # noqa: F401

    tracemalloc.start()
    one_line_refusal(
        arguments,
        f"'buffer/observations' declares ({rows}, 1, {size}) float32; "
        f"this run's holds (<=1000, 1, {size}) float32",
    )
    assert tracemalloc.get_traced_memory()[1] < 100 * 2**20
    tracemalloc.stop()
    (folder / "checkpoint.npz").write_bytes(oversized_buffer_checkpoint((10, 1, size), ("secrets",)))
    one_line_refusal(arguments, "'buffer/secrets' is not part of this run's checkpoint")


def test_expected_arrays_admit_what_a_run_writes_and_nothing_else():
    from planner.model_file import ExpectedArray, header_check

    float32 = np.dtype(np.float32)
    check = header_check(
        {
            "q/0.weight": (ExpectedArray((4, 3), float32),),
            "optimizer/0/*": (ExpectedArray((4, 3), float32), ExpectedArray(())),
            "buffer/rewards": (ExpectedArray((100, 1), float32, at_most_rows=True),),
        }
    )
    for name, shape in (("q/0.weight", (4, 3)), ("optimizer/0/exp_avg", (4, 3)), ("optimizer/0/step", ())):
        assert check(name, shape, float32) is None
    assert (
        check("buffer/rewards", (0, 1), float32) is None
        and check("buffer/rewards", (100, 1), float32) is None
    )
    assert check("q/0.weight", (4, 3), np.dtype(np.float64)) == (
        "declares (4, 3) float64; this run's holds (4, 3) float32"
    )
    assert check("buffer/rewards", (101, 1), float32) == (
        "declares (101, 1) float32; this run's holds (<=100, 1) float32"
    )
    assert check("buffer/rewards", (10, 2), float32) is not None
    assert check("optimizer/1/exp_avg", (4, 3), float32) == "is not part of this run's checkpoint"


@pytest.mark.parametrize("kind", ["fifo", "zero device", "not rrd", "many"])
def test_view_checks_what_it_opens_before_the_viewer_starts(tmp_path, kind):
    import os

    path = tmp_path / "x.rrd"
    if kind == "fifo":
        os.mkfifo(path)
        expected = "not a regular file"
    elif kind == "zero device":
        path.symlink_to("/dev/zero")
        expected = "not a regular file"
    elif kind == "not rrd":
        path.write_bytes(b"PK\x03\x04 not a recording")
        expected = "not a rerun recording"
    else:
        (path := tmp_path / "folder").mkdir()
        for index in range(1001):
            (path / f"episode-{index:04d}.rrd").write_bytes(b"RRF2")
        expected = "holds 1001 recordings; the viewer opens at most 1000"
    one_line_refusal(["view", str(path)], expected)


def test_view_without_a_display_suggests_web(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    (recording := tmp_path / "x.rrd").write_bytes(b"RRF2")
    one_line_refusal(["view", str(recording)], "no display to open the viewer on (DISPLAY is not set); --web")


def test_the_native_viewer_serves_on_the_loopback_only(tmp_path):
    from stack.apps.view import viewer_command

    command, _ = viewer_command([tmp_path / "x.rrd"], web=False)
    assert command[1:3] == ["--bind", "127.0.0.1"]


def test_the_printed_view_command_is_shell_quoted(tmp_path):
    import shlex

    out = tmp_path / "a b 'c' $HOME [x]"
    result = CliRunner().invoke(
        app,
        ["run", "-c", str(tiny_config_file(tmp_path)), "--agent", "keep-lane", "--episodes", "1", "--record"]
        + ["--out", str(out), "--no-progress"],
    )
    assert result.exit_code == 0, result.output
    (line,) = [line for line in result.output.splitlines() if "drivestack view" in line]
    assert shlex.split(line.split(": ", 1)[1]) == ["drivestack", "view", str(out), "--worst"]


def test_export_reports_the_file_it_wrote(tmp_path):
    """stable-baselines3 appends .zip to a name without a suffix only."""
    from pathlib import Path

    from planner.factory import SHIPPED_MODELS
    from stack.apps.folders import written_file

    assert (written_file(Path("plain")), written_file(Path("m.zip"))) == (Path("plain.zip"), Path("m.zip"))
    result = CliRunner().invoke(
        app, ["export", str(SHIPPED_MODELS["dqn"]), "--sb3", str(tmp_path / "x.tar.gz")]
    )
    assert result.exit_code == 0, result.output
    assert f"wrote {tmp_path / 'x.tar.gz'}:" in result.output
    assert [path.name for path in tmp_path.iterdir()] == ["x.tar.gz"]


def test_export_to_an_empty_name_is_one_line():
    from planner.factory import SHIPPED_MODELS

    one_line_refusal(["export", str(SHIPPED_MODELS["dqn"]), "--sb3", ""], "--sb3: expected a file name")


def test_the_same_command_into_its_own_finished_folder_says_so(tmp_path):
    from stack.runtime.owner import MARKER, Owner, refusal

    (tmp_path / "summary.json").write_text("{}")
    owner = Owner("train-ddqn", "abc")
    (tmp_path / MARKER).write_text(json.dumps({"command": owner.command, "config": owner.config}))
    why = refusal(tmp_path, owner, resuming=False, restart=False)
    assert why is not None and "with these arguments and config" in why and "other" not in why


def test_a_safety_run_stopped_after_its_last_point_is_not_interrupted(tmp_path, monkeypatch, capsys):
    import stack.apps.safety as safety

    def every_point_then_stop(task, items, jobs, ray=None):
        for index, item in enumerate(items):
            yield index, task(item)
        raise KeyboardInterrupt

    monkeypatch.setattr(safety, "completed", every_point_then_stop)
    monkeypatch.setattr(safety, "grid", lambda kind, quick: safety_points(kind))
    from stack.settings.run import build_config

    config = build_config({"highway": {"lanes_count": 3}, "planner": {"agent": "keep-lane"}})
    (out := tmp_path / "s").mkdir()
    assert safety.assess_and_report(config, ("lead-braking",), True, out, 1, False) is False
    assert "interrupted" not in capsys.readouterr().out


def safety_points(kind):
    from stack.sim.safety_scenarios import Point

    return [Point(kind, (20.0, 2.0, 2.0))]


def test_errors_about_worlds_name_the_option(tmp_path):
    one_line_refusal(["train", "--worlds", "5000", "--out", str(tmp_path / "t")], "--worlds: train.worlds")


def test_out_as_a_dangling_link_says_so(tmp_path):
    (out := tmp_path / "out").symlink_to(tmp_path / "missing")
    one_line_refusal(["run", "--out", str(out)], f"--out: {out} is a link to a missing folder")


def test_a_viewer_that_cannot_open_a_window_is_one_line_suggesting_web(tmp_path, monkeypatch, capsys):
    import sys

    import stack.apps.view as viewing

    crash = "import sys; sys.stderr.write('\\x1b[31mwinit: no display\\n'); sys.exit(1)"
    failing = [sys.executable, "-c", crash]
    monkeypatch.setattr(viewing, "viewer_command", lambda recordings, web: (failing, None))
    assert viewing.view([tmp_path / "x.rrd"], web=False) == 1
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1 and "--web serves it to a browser" in error
    assert "winit" not in error


def digits_model(path: Path) -> None:
    """A model file whose metadata holds an integer of 4,400 digits (more than Python converts)."""
    from planner.model_file import FORMAT
    from tests.test_model_files import npy, plain_mlp, write

    arrays, metadata = plain_mlp()
    text = json.dumps({"format": FORMAT, **metadata})[:-1] + ', "trained_steps": ' + "9" * 4400 + "}"
    members = {"metadata.npy": npy(np.frombuffer(text.encode(), dtype=np.uint8))}
    write(path, members | {f"array/{name}.npy": npy(value) for name, value in arrays.items()})


def test_a_model_whose_metadata_holds_a_4400_digit_integer_is_one_line_naming_it(tmp_path):
    digits_model(model := tmp_path / "digits.npz")
    expected = f"{model}: model metadata is not valid JSON (or holds an integer too long to read)"
    arguments = ["run", "--agent", "ddqn", "--model", str(model), "--out", str(tmp_path / "r")]
    one_line_refusal(arguments, expected)
    arguments = ["train", "--set", f"train.init_model={model}", "--out", str(tmp_path / "t")]
    one_line_refusal(arguments, expected)
