"""Property-based hostile input (hypothesis): whatever a config or a CLI override holds, loading it
either gives a valid config or one line naming the key, never another exception; through the CLI,
exit code 2 and one line; a crafted model file is refused in one line without growing memory."""

import json
import resource
import string

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.settings.run import ConfigError, build_config, config_text, load_config

SECTIONS = {
    "highway": ["lanes_count", "vehicles_count", "vehicles_density", "duration", "traffic", "road"],
    "perception": ["cells_ahead", "cells_behind", "lanes", "features", "lateral_reach", "sensor"],
    "planner": ["agent", "model", "safety", "oracle"],
    "controller": ["type", "pid", "mpc", "lane_change_duration_s"],
    "train": ["steps", "envs", "scenarios", "buffer_size", "reward", "validation"],
    "sim": ["backend", "plant"],
}
METADATA_KEYS = ["kind", "algorithm", "encoding", "observation_size", "actions", "hidden", "grid", "format"]
KEYS = ["seed", "episodes", "decision_period_s", "control_rate_hz", "scenario", *SECTIONS]
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**80), max_value=2**80),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(alphabet=string.printable, max_size=50),
)
values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=12), inner, max_size=4),
    max_leaves=12,
)
section = st.sampled_from(list(SECTIONS)).flatmap(
    lambda name: st.tuples(
        st.just(name), st.dictionaries(st.sampled_from(SECTIONS[name]), values, max_size=3)
    )
)
configs = st.dictionaries(st.sampled_from(KEYS), values, max_size=4) | st.builds(
    dict, st.lists(section, max_size=3)
)


def one_line_or_valid(load) -> None:
    """`load()` refuses in one line, or gives a config whose resolved YAML (a results folder's
    config.yaml, which `--resume` reads) loads back to the same config."""
    try:
        config = load()
    except ConfigError as error:
        message = str(error)
        assert "\n" not in message and len(message) <= 300, message[:400]
        return
    assert build_config(yaml.safe_load(config_text(config)), "config.yaml") == config


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(configs)
def test_any_config_data_loads_or_is_one_line(data):
    one_line_or_valid(lambda: build_config(data, "hostile.yaml"))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(configs)
def test_any_config_file_loads_or_is_one_line(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("hostile") / "config.yaml"
    try:
        path.write_text(yaml.safe_dump(data))
    except yaml.YAMLError:
        path.write_text(json.dumps(data, default=str))
    one_line_or_valid(lambda: load_config(path))


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(KEYS + [f"{s}.{k}" for s, keys in SECTIONS.items() for k in keys]), values)
def test_any_override_loads_or_is_one_line(key, value):
    one_line_or_valid(
        lambda: build_config({}, "config", {key: f"--set {key}"}, **{key.replace(".", "__"): value})
    )


def test_a_path_from_the_home_of_no_user_is_one_line():
    """`~0` (the home of a user named 0) found by the property above: pathlib raised a RuntimeError."""
    for key, value in (("planner__model", "~0"), ("planner__agent", "~0/agent.py:Agent")):
        with pytest.raises(ConfigError, match="no home directory for its '~'"):
            build_config({}, "config", **{key: value})


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(METADATA_KEYS), values, max_size=4))
def test_any_model_metadata_loads_or_is_one_line(tmp_path_factory, changes):
    from planner.learned import load_agent
    from planner.model_file import ModelFileError
    from tests.test_model_files import with_metadata

    path = tmp_path_factory.mktemp("model") / "crafted.npz"
    with_metadata(path, **changes)
    before = peak_rss_mb()
    try:
        load_agent(path)
    except ModelFileError as error:
        assert "\n" not in str(error) and len(str(error)) <= 400, str(error)[:500]
    assert peak_rss_mb() - before < 50


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(configs)
def test_any_config_file_through_the_cli_is_exit_2_and_one_line(tmp_path_factory, data):
    """As a user would meet it: `drivestack run -c FILE --out <a file>` ends before any work with
    exit code 2 and one line (the config's error, or, for a valid config, the output location),
    never a traceback, and the process's peak memory does not grow by more than 50 MB."""
    folder = tmp_path_factory.mktemp("cli")
    (path := folder / "config.yaml").write_text(
        yaml.safe_dump(data) if _dumps(data) else json.dumps(data, default=str)
    )
    (existing := folder / "results.txt").write_text("keep")
    before = peak_rss_mb()
    result = CliRunner().invoke(app, ["run", "-c", str(path), "--out", str(existing)])
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and len(lines[0]) <= 300, result.output[:500]
    assert "Traceback" not in result.output and existing.read_text() == "keep"
    assert peak_rss_mb() - before < 50


def _dumps(data: object) -> bool:
    try:
        yaml.safe_dump(data)
    except yaml.YAMLError:
        return False
    return True


sweep_spaces = st.dictionaries(
    st.sampled_from(["seed", "train.gamma", "train.steps", "train.network", "train.lr", "scenario", "x..y"]),
    values
    | st.lists(scalars, max_size=3)
    | st.dictionaries(
        st.sampled_from(["uniform", "loguniform", "randint", "choice", "normal"]),
        st.lists(st.integers(-3, 3) | st.floats(allow_nan=True) | scalars, max_size=3) | values,
        max_size=2,
    ),
    max_size=3,
)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    sweep_spaces,
    st.integers(min_value=1, max_value=3) | values,
    st.sampled_from(["mean_return", "collision_rate"]) | values,
)
def test_any_sweep_file_loads_or_is_one_line(tmp_path_factory, space, samples, metric):
    """A sweep file is refused in one line, or every trial it can start (each grid value, choice
    and range end) loads: no trial fails on its config an hour later."""
    from stack.settings.sweep import candidates, load_sweep, trial_config

    folder = tmp_path_factory.mktemp("sweep")
    (folder / "base.yaml").write_text("episodes: 1\n")
    data = {"config": "base.yaml", "space": space, "samples": samples, "metric": metric}
    (folder / "sweep.yaml").write_text(json.dumps(data, default=str))
    try:
        sweep, base, _ = load_sweep(folder / "sweep.yaml")
    except ConfigError as error:
        assert "\n" not in str(error) and len(str(error)) <= 300, str(error)[:400]
        return
    assert sweep.metric == metric
    for key, values in sweep.space.items():
        for value in candidates(values):
            trial_config(base, sweep.fixed, {key: value})
