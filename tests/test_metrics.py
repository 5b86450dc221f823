import numpy as np
import pytest

from records import Actuation, Reference
from stack.apps.compare import intervals, markdown
from stack.loop.loop_records import Tick
from stack.loop.metrics import EpisodeRecorder
from stack.results.episode_fields import columns, reported, summary_rows
from stack.results.episode_measures import lateral_comfort, measured, moving_average
from stack.results.episode_result import TIMING_FIELDS, EpisodeResult, summarize
from stack.runs.episodes import RunResults
from tests.helpers import scene


def result(crashed: bool, passed: int) -> EpisodeResult:
    return EpisodeResult(0, 0, 10, 1.0, crashed, passed, 0, 20.0, 0.0, 0.0)


def test_a_vehicle_counts_as_passed_once():
    ahead = scene(3, (0.0, 1), [(20.0, 4.0), (-30.0, 0.0)])
    recorder = EpisodeRecorder(ahead)
    reference, actuation = Reference(4.0, 0.0, 0.0, set_speed=25.0), Actuation(0.0, 0.01)
    for ego_x in (25.0, 10.0, 30.0):
        recorder.record(Tick(reference, actuation, scene(3, (ego_x, 1), [(20.0, 4.0), (-30.0, 0.0)]), 1, 1))
    assert np.flatnonzero(recorder.passed).tolist() == [1] and recorder.passed_cars == 1, (
        "passed once; a car that was always behind never counts"
    )
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


def test_time_in_the_leftmost_lane_counts_the_ticks_that_end_there():
    recorder = EpisodeRecorder(scene(3, (0.0, 0)))
    reference, actuation = Reference(0.0, 0.0, 0.0, set_speed=25.0), Actuation(0.0, 0.0)
    for tick, lane in enumerate((0, 1, 0, 0, 2), start=1):
        recorder.record(Tick(reference, actuation, scene(3, (2.0 * tick, lane), time=0.1 * tick), lane, lane))
    leftmost_s = measured(EpisodeResult, recorder.samples(0.1))["time_in_leftmost_lane_s"]
    assert leftmost_s == pytest.approx(0.3), "the start is no tick"


def episode(number: int, crashed: bool, leftmost_s: float) -> EpisodeResult:
    return EpisodeResult(
        number, number, 10, 1.0, crashed, 0, 1, 20.0, 0.5, 0.8, time_in_leftmost_lane_s=leftmost_s
    )


def test_the_summary_the_run_table_and_compare_follow_the_fields_declarations():
    episodes = [episode(0, False, 2.0), episode(1, True, 4.0)]
    summary = summarize(episodes, agent="rule")
    assert list(summary)[:8] == [
        "agent",
        "episodes",
        "collisions",
        "collision_rate",
        "at_fault_collisions",
        "not_at_fault_collisions",
        "road_departures",
        "failures",
    ]
    assert list(summary)[-4:] == ["peak_lat_jerk", "mpc_fallbacks", "solve_ms_p50", "solve_ms_p95"]
    assert summary["time_in_leftmost_lane_s"] == 3.0 and summary["not_at_fault_collisions"] == 1
    rows = dict(summary_rows(EpisodeResult, summary))
    assert rows["time in the leftmost lane / episode"] == "3.00 s"
    assert rows["collision rate"] == "50.0% (1)" and rows["accuracy"] == "0.00 %"
    assert dict(summary_rows(EpisodeResult, summarize([episode(0, False, 0.0)])))["accuracy"] == "n/a"
    found = intervals(RunResults(summary, episodes, []))
    assert list(found)[:3] == ["collision_rate", "at_fault_rate", "road_departure_rate"]
    assert found["time_in_leftmost_lane_s"].value == 3.0 and found["collision_rate"].value == 0.5
    assert "| leftmost lane s / ep |" in markdown(
        [{**summary, "intervals": {k: v.as_list() for k, v in found.items()}}]
    )


def test_wall_clock_fields_go_to_timings_only():
    assert TIMING_FIELDS == ("solve_ms_p50", "solve_ms_p95")
    recorded = episode(0, False, 1.0)
    assert not set(TIMING_FIELDS) & set(recorded.outcome_row())
    assert list(recorded.timing_row()) == ["episode", "seed", *TIMING_FIELDS]
    assert "time_in_leftmost_lane_s" in recorded.outcome_row()


def test_every_reported_field_names_its_time_unit():
    declared = {field.name: how.unit for field, how in reported(EpisodeResult)}
    assert len(declared) == len(EpisodeResult.__dataclass_fields__) - 2, "all but the trace and snapshot"
    for name, unit in declared.items():
        assert (f"_{unit}_" in f"{name}_") == (unit in ("s", "ms")), name


def test_run_s_table_of_episodes_is_made_from_the_declarations():
    episode = EpisodeResult(
        episode=3,
        seed=7,
        steps=600,
        duration_s=40.0,
        crashed=True,
        passed_cars=4,
        lane_changes=2,
        mean_speed=21.456,
        peak_lat_accel=1.234,
        peak_lat_jerk=2.345,
        road_departure=False,
        at_fault_collision=True,
        collision_kind="rear-end",
        min_ttc_s=0.44,
        emergency_brakings=1,
    )
    shown = columns(EpisodeResult, "episodes")
    cells = {column.header: column.cell(episode.row()) for column in shown}
    assert list(cells) == [
        "episode",
        "seed",
        "crashed",
        "fault",
        "off road",
        "min TTC [s]",
        "AEB",
        "passed",
        "mean speed [m/s]",
        "lane changes",
        "fallback",
        "peak |a_y| [m/s²]",
        "peak jerk [m/s³]",
    ]
    assert list(cells.values()) == [
        "3",
        "7",
        "yes",
        "rear-end (at fault)",
        "no",
        "0.4",
        "1",
        "4",
        "21.46",
        "2",
        "0",
        "1.23",
        "2.35",
    ]
