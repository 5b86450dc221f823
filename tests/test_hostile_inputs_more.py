"""Issue 73's hostile and careless cases: a config that validates runs to its end, nothing coerced
or mixed silently, the Python API as strict as the CLI; each refusal one line with the right exit
code."""

from __future__ import annotations

import json
import shutil

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
    from stack.sim.batched.traffic import TrafficBatch

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
    from planner.factory import SHIPPED_MODELS

    monkeypatch.chdir(tmp_path)
    shutil.copy(SHIPPED_MODELS["dqn"], tmp_path / "dqn.npz")
    config = tiny_config_file(tmp_path)
    arguments = ["run", "-c", str(config), "--agent", "dqn", "--model", "dqn.npz", "--episodes", "1"]
    result = CliRunner().invoke(app, [*arguments, "--out", "out", "--no-progress"])
    assert result.exit_code == 0, result.output
    written = yaml.safe_load((tmp_path / "out" / "config.yaml").read_text())
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
    from stack.training.vector_env import DecisionVecEnv

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

    from stack.training.vector_env import DecisionVecEnv

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
