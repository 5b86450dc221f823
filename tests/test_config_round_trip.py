"""A results folder's config.yaml is the config that ran: read back, it is the same config and
drives the same episodes (issue 52: a file naming its scenario used to re-apply the scenario's
whole world over the keys it set)."""

from __future__ import annotations

import pytest
import yaml
from hypothesis import given, reject, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.apps.options import RUN_CONFIG, TRAIN_CONFIG
from stack.settings.run import ConfigError, build_config, config_text, load_config
from stack.worlds import scenarios

WORLD_SETS = {
    "highway.duration": st.integers(2, 60),
    "highway.vehicles_count": st.integers(1, 80),
    "highway.lanes_count": st.integers(2, 6),
    "highway.vehicles_density": st.floats(0.5, 3.0),
    "perception.sensor.position_noise_m": st.floats(0.0, 2.0),
    "perception.sensor.miss_probability": st.floats(0.0, 0.5),
    "controller.set_speed_mps": st.floats(10.0, 36.0),
    "seed": st.integers(0, 10_000),
}


@settings(max_examples=60, deadline=None)
@given(
    scenario=st.sampled_from(scenarios.names()),
    base=st.sampled_from([RUN_CONFIG, TRAIN_CONFIG]),
    sets=st.dictionaries(st.sampled_from(sorted(WORLD_SETS)), st.none(), max_size=4).flatmap(
        lambda keys: st.fixed_dictionaries({key: WORLD_SETS[key] for key in keys})
    ),
)
def test_any_set_over_any_scenario_reads_back_as_the_config_that_ran(scenario, base, sets, tmp_path_factory):
    overrides = {key.replace(".", "__"): value for key, value in sets.items()}
    try:
        ran = load_config(base, scenario=scenario, **overrides)
    except ConfigError:
        reject()
    written = tmp_path_factory.mktemp("folder") / "config.yaml"
    written.write_text(config_text(ran, "the resolved config"))
    assert load_config(written) == ran


def test_a_file_naming_its_scenario_keeps_the_world_keys_it_sets():
    config = build_config({"scenario": "jam", "highway": {"duration": 7}, "perception": {"sensor": {}}})
    jam = build_config({"scenario": "jam"})
    assert config.highway.duration == 7 and jam.highway.duration != 7
    assert config.highway.model_copy(update={"duration": jam.highway.duration}) == jam.highway


def test_the_scenario_option_moves_a_config_to_that_world():
    """`--scenario` replaces the world, the config's own keys included (as before)."""
    config = build_config({"scenario": "jam", "highway": {"duration": 7}}, scenario="overtaking")
    assert config.highway == build_config({"scenario": "overtaking"}).highway


@pytest.mark.parametrize("scenario", ["overtaking", "random"])
def test_run_from_a_folders_config_reproduces_its_episodes_byte_for_byte(tmp_path, scenario):
    first, again = tmp_path / "first", tmp_path / "again"
    sets = ["--set", "highway.duration=3", "--set", "highway.vehicles_count=9", "--set", "seed=41"]
    ran = CliRunner().invoke(
        app,
        ["run", "--scenario", scenario, "--agent", "mobil", "--episodes", "2", *sets, "--out", str(first)],
    )
    assert ran.exit_code == 0, ran.output
    written = yaml.safe_load((first / "config.yaml").read_text())
    assert written["highway"]["duration"] == 3 and written["highway"]["vehicles_count"] == 9
    rerun = CliRunner().invoke(app, ["run", "--config", str(first / "config.yaml"), "--out", str(again)])
    assert rerun.exit_code == 0, rerun.output
    assert (again / "episodes.csv").read_bytes() == (first / "episodes.csv").read_bytes()
    assert (again / "config.yaml").read_text().split("\n", 1)[1] == (first / "config.yaml").read_text().split(
        "\n", 1
    )[1]


@pytest.mark.slow
@pytest.mark.parametrize("scenario", scenarios.names())
def test_every_scenario_reproduces_from_its_folder(tmp_path, scenario):
    test_run_from_a_folders_config_reproduces_its_episodes_byte_for_byte(tmp_path, scenario)


def test_every_sweep_trial_keeps_the_fixed_world_keys(tmp_path):
    """Issue 52 (2): the trials read the sweep's written base config; its world keys stay."""
    from stack.apps.sweep import BASE, prepare
    from stack.settings.sweep import load_sweep, trial_config

    fixed = {"train.scenarios": {}, "train.members": 1, "highway.duration": 6, "highway.vehicles_count": 12}
    spec = {"config": str(TRAIN_CONFIG), "fixed": fixed, "space": {"train.gamma": [0.9, 0.95]}}
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(spec))
    sweep, base, _ = load_sweep(tmp_path / "sweep.yaml")
    (tmp_path / "sweep").mkdir()
    prepare(sweep, base, tmp_path / "sweep")
    trial = trial_config(tmp_path / "sweep" / BASE, {}, {"train.gamma": 0.9})
    assert (trial.highway.duration, trial.highway.vehicles_count, trial.train.gamma) == (6, 12, 0.9)
