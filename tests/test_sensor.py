import math

import numpy as np
import pytest
from pydantic import ValidationError

from perception.sensor import PHANTOM_ID_BASE, SensorConfig, SensorModel
from stack.settings.run import ConfigError, build_config
from tests.helpers import scene

WORLD = scene(3, (0.0, 1), [(10.0, 0.0), (30.0, 4.0), (-70.0, 8.0), (120.0, 0.0)])


def test_off_by_default_returns_the_truth():
    assert SensorModel(SensorConfig()).observe(WORLD) is WORLD


def test_limited_range_drops_far_vehicles_but_never_the_ego():
    seen = SensorModel(SensorConfig(range_m=50.0)).observe(WORLD)
    assert seen.ids.tolist() == [0, 1, 2]


def test_missed_detections_and_seeded_noise():
    blind = SensorModel(SensorConfig(miss_probability=1.0)).observe(WORLD)
    assert blind.ids.tolist() == [0]
    noisy = [SensorModel(SensorConfig(position_noise_m=0.5), seed=3).observe(WORLD) for _ in range(2)]
    np.testing.assert_array_equal(noisy[0].s, noisy[1].s)
    assert noisy[0].s[0] == WORLD.s[0] and noisy[0].d[0] == WORLD.d[0]
    spread = noisy[0].s[1:] - WORLD.s[1:]
    assert 0 < np.abs(spread).max() < 3.0
    other_seed = SensorModel(SensorConfig(position_noise_m=0.5), seed=4).observe(WORLD)
    assert not np.array_equal(other_seed.s, noisy[0].s)


def test_false_positives_appear_near_the_ego_on_lane_centres():
    model = SensorModel(SensorConfig(false_positives=3.0, false_positive_range_m=40.0), seed=1)
    counts = []
    for _ in range(200):
        seen = model.observe(WORLD)
        phantoms = seen.ids >= PHANTOM_ID_BASE
        counts.append(phantoms.sum())
        assert np.all(np.abs(seen.s[phantoms] - WORLD.s[0]) <= 40.0)
        assert set(seen.d[phantoms].tolist()) <= {0.0, 4.0, 8.0}
    assert np.mean(counts) == pytest.approx(3.0, abs=0.4)


@pytest.mark.parametrize(
    ("sensor", "key"),
    [
        ({"miss_probability": 1.5}, "miss_probability"),
        ({"position_noise_m": -1}, "position_noise_m"),
        ({"range_m": 0}, "range_m"),
        ({"blur": 1}, "blur"),
    ],
)
def test_bad_sensor_config_names_the_key(sensor, key):
    with pytest.raises(ConfigError, match=f"perception.sensor.{key}"):
        build_config({"perception": {"sensor": sensor}})
    with pytest.raises(ValidationError):
        SensorConfig(**sensor)


def test_sensor_is_enabled_only_when_something_is_set():
    assert not SensorConfig().enabled
    assert SensorConfig(range_m=80.0).enabled and SensorConfig(range_m=math.inf).enabled is False
