from pathlib import Path

import pytest
import yaml

from stack.settings.run import ConfigError, load_config

ROOT = Path(__file__).resolve().parents[1]


def write(tmp_path, data) -> Path:
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_default_config_loads():
    config = load_config(ROOT / "configs/highway.yaml")
    assert config.highway.lanes_count == 4
    assert config.highway.vehicles_count == 50
    assert config.highway.duration == 40
    assert config.control_rate_hz == config.highway.simulation_frequency == 15
    assert config.decision_ticks == 15
    assert config.planner.agent == "ddqn"
    assert config.perception.cells_ahead == 12


def test_overrides_replace_file_values(tmp_path):
    config = load_config(write(tmp_path, {"seed": 3}), seed=7, episodes=2, planner__agent="keep-lane")
    assert (config.seed, config.episodes, config.planner.agent) == (7, 2, "keep-lane")


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        ({"highway": {"lanes_count": 0}}, "highway.lanes_count: Input should be greater than or equal to 1"),
        ({"highway": {"duration": -5}}, "highway.duration: Input should be greater than 0"),
        ({"highway": {"lanes": 3}}, "highway.lanes: unknown key"),
        ({"episodes": "many"}, "episodes: Input should be a valid integer"),
        ({"decision_period_s": 0.01}, "decision_period_s: must be at least one control tick"),
        ({"control_rate_hz": 10}, "control_rate_hz: must equal highway.simulation_frequency"),
        (
            {"planner": {"agent": "genius"}},
            "planner.agent: unknown agent 'genius'; available: ddqn, dqn, tabular, rule",
        ),
        ({"controller": {"type": "lqr2"}}, "controller.type: unknown controller 'lqr2'"),
        (
            {"perception": {"cell_length": 0}},
            "perception.cell_length: Input should be greater than or equal to 0.5",
        ),
    ],
)
def test_bad_values_fail_with_one_line_naming_the_key(tmp_path, data, expected):
    path = write(tmp_path, data)
    with pytest.raises(ConfigError) as error:
        load_config(path)
    message = str(error.value)
    assert message.startswith(f"{path}: {expected}")
    assert "\n" not in message


def test_override_is_validated_too(tmp_path):
    with pytest.raises(ConfigError, match="episodes: Input should be greater than or equal to 1"):
        load_config(write(tmp_path, {}), episodes=0)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "absent.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("highway: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML at line"):
        load_config(broken)
    listed = tmp_path / "list.yaml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="expected a mapping"):
        load_config(listed)


@pytest.mark.parametrize(
    "path", sorted((ROOT / "stack" / "configs").rglob("*.yaml")), ids=lambda path: path.name
)
def test_every_packaged_config_loads(path):
    """The run config and each shipped model's training config validate as they ship."""
    config = load_config(path)
    if "train" in path.parts:
        assert config.planner.agent == config.train.algorithm
