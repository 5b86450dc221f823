import numpy as np
import pytest

from records import Actuation, Reference
from stack.loop.loop_records import Tick
from stack.loop.metrics import EpisodeRecorder, EpisodeResult, lateral_comfort, moving_average, summarize
from tests.helpers import scene


def result(crashed: bool, passed: int) -> EpisodeResult:
    return EpisodeResult(0, 0, 10, 1.0, crashed, passed, 0, 20.0, 0.0, 0.0)


def test_a_vehicle_counts_as_passed_once():
    ahead = scene(3, (0.0, 1), [(20.0, 4.0), (-30.0, 0.0)])
    recorder = EpisodeRecorder(ahead)
    reference, actuation = Reference(4.0, 0.0, 0.0, set_speed=25.0), Actuation(0.0, 0.01)
    for ego_x in (25.0, 10.0, 30.0):
        recorder.record(Tick(reference, actuation, scene(3, (ego_x, 1), [(20.0, 4.0), (-30.0, 0.0)]), 1, 1))
    assert recorder.passed == {1}, "passed once; a car that was always behind never counts"
    assert recorder.d_reference == [4.0] * 3 and recorder.steering == [0.01] * 3
    assert len(recorder.time) == 4, "the start and the world after each tick"


def test_accuracy_and_rates():
    summary = summarize([result(False, 9), result(True, 0)], agent="rule")
    assert summary["accuracy"] == pytest.approx(90.0)
    assert summary["collision_rate"] == 0.5
    assert summary["agent"] == "rule"


def test_moving_average_and_comfort_of_a_constant_turn():
    np.testing.assert_allclose(moving_average(np.array([0.0, 2.0, 4.0, 6.0]), 2), [0.0, 1.0, 3.0, 5.0])
    dt, speed, yaw_rate = 0.1, 20.0, 0.05
    heading = np.arange(30) * yaw_rate * dt
    accel, jerk = lateral_comfort(heading, np.full(30, speed), dt)
    assert accel == pytest.approx(speed * yaw_rate)
    assert jerk == pytest.approx(0.0, abs=1e-9)
