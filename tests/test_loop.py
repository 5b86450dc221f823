import dataclasses

import numpy as np
import pytest

from controllers.leaders import leaders
from planner.factory import make_agent
from records import Command
from stack.loop.closed_loop import ClosedLoop, grid_config
from stack.loop.loop_records import LoopStatus, SolveStatistics
from stack.results.episode_result import outcome
from stack.runs.alone import run_agent_episode
from stack.runs.episodes import run
from stack.settings.run import build_config
from stack.sim.empty_road import EmptyRoad
from stack.sim.highway import HighwayAdapter

LANE_CHANGE = {"seed": 2, "highway": {"vehicles_count": 20, "duration": 20}, "perception": {"cells_ahead": 9}}
"""From its drivable start the ego meets slower traffic after ~14 s and changes lane to the left."""


def run_one(data: dict):
    config = build_config(data)
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        agent = make_agent(config.planner.agent, config.highway.lanes_count, grid_config(config))
        return run_agent_episode(ClosedLoop(config, adapter), agent, 0, config.seed)


def test_rule_agent_changes_lane_by_its_own_steering():
    result = run_one(LANE_CHANGE)
    d = np.array(result.trace["d"])
    assert not result.crashed
    assert result.lane_changes >= 1
    assert d[0] == 12.0
    assert abs(d[-1] - 8.0) < 0.05, "ends on the centre of the lane to the left"
    assert np.max(np.abs(np.diff(d))) < 0.15, "a smooth, steered lateral motion, not a jump"
    assert result.peak_lat_accel < 3.0


def test_lane_change_holds_the_target_lane_centre():
    result = run_one(LANE_CHANGE)
    time, d = np.array(result.trace["time"]), np.array(result.trace["d"])
    settled = d[time > time[-1] - 1.5]
    assert np.all(np.abs(settled - 8.0) < 0.05)


def test_same_seed_gives_identical_summary(tiny_config):
    first = run(tiny_config, progress=False)
    second = run(tiny_config, progress=False)
    assert outcome(first.summary) == outcome(second.summary)
    assert [e.trace for e in first.episodes] == [e.trace for e in second.episodes]


def test_different_seeds_give_different_traffic(tiny_config):
    first = run(tiny_config, progress=False)
    other = run(tiny_config.model_copy(update={"seed": 5}), progress=False)
    assert first.episodes[0].trace != other.episodes[0].trace


def test_keep_lane_agent_never_leaves_its_lane(tiny_config):
    result = run_one({**tiny_config.model_dump(), "planner": {"agent": "keep-lane"}})
    d = np.array(result.trace["d"])
    assert result.lane_changes == 0
    assert np.ptp(d) < 1e-6


@pytest.mark.slow
def test_parallel_episodes_give_the_same_results_as_serial(tiny_config):
    """Slow: two spawned processes (~10 CPU-s of start-up); the default suite's
    `test_batched_episodes.py::test_a_run_is_the_same_in_batches_and_over_processes` asserts the
    same on the same path (batched worlds over `jobs=2`)."""
    config = tiny_config.model_copy(update={"episodes": 3})
    serial = run(config, progress=False, jobs=1)
    parallel = run(config, progress=False, jobs=2)
    assert outcome(parallel.summary) == outcome(serial.summary)
    assert [outcome(e.row()) for e in parallel.episodes] == [outcome(e.row()) for e in serial.episodes]


def test_fast_and_stock_backends_drive_the_same_episode(tiny_config):
    stock = tiny_config.model_copy(update={"sim": tiny_config.sim.model_copy(update={"backend": "stock"})})
    assert run(stock, progress=False).episodes[0].trace == run(tiny_config, progress=False).episodes[0].trace


def test_noisy_sensor_runs_are_seeded_and_change_what_the_planner_sees(tiny_config):
    noisy = build_config(
        {
            **tiny_config.model_dump(),
            "perception": {
                "sensor": {"position_noise_m": 1.0, "false_positives": 2.0},
                "tracker": {"mode": "off"},
            },
        }
    )
    first, second = run(noisy, progress=False), run(noisy, progress=False)
    assert outcome(first.summary) == outcome(second.summary)
    grid_truth = run(tiny_config, progress=False).episodes[0].snapshot[1].cells
    assert not np.array_equal(first.episodes[0].snapshot[1].cells, grid_truth)


def test_safety_and_cruise_act_on_the_perceived_world(tiny_config):
    raw = {"sensor": {"false_positives": 4.0}, "tracker": {"mode": "off"}}
    sensed = {**tiny_config.model_dump(), "perception": raw}
    perceived = build_config(sensed)
    truth = build_config(sensed, perception__control_on_ground_truth=True)
    with HighwayAdapter(perceived.highway, perceived.sim.backend) as adapter:
        loop = ClosedLoop(perceived, adapter)
        loop.reset(1)
        phantoms = loop.perceived.count - loop.world.count
        reference = loop.maneuver.reference(loop.perceived)
        assert phantoms > 0 and loop.perceived.ids[-1] >= 1_000_000, "the sensor's phantoms are in it"
        assert reference.leaders == leaders(loop.perceived, (loop.maneuver.lane,))
        ground = ClosedLoop(truth, adapter)
        ground.reset(1)
        assert ground.perceived is ground.world
    assert run(perceived, progress=False).summary != run(truth, progress=False).summary


def test_a_tick_is_a_frozen_record_its_consumers_read_outside_it(tiny_config):
    """`tick()` changes the world and returns what it did; `act` hands each record to the
    recorder and the safety monitor; a fork plays on without moving the loop it came from."""
    with HighwayAdapter(tiny_config.highway, tiny_config.sim.backend) as adapter:
        loop = ClosedLoop(tiny_config, adapter)
        start = loop.reset(1)
        loop.perceive()
        tick = loop.tick()
        assert tick.world is loop.world and tick.world.time > start.time
        assert (tick.lane, tick.target, tick.changing_lane) == (start.ego_lane, start.ego_lane, False)
        with pytest.raises(dataclasses.FrozenInstanceError):
            tick.lane = 0  # type: ignore[misc]
        assert loop.traces().time.tolist() == [start.time], "a tick alone is recorded by none of them"
        future = loop.fork()
        assert future.act(Command.STAY, ticks=3).ticks == 3 and future.world.time > loop.world.time
        with pytest.raises(RuntimeError, match="a fork records no metrics"):
            future.traces()
        assert loop.world is tick.world, "the fork moved alone"
        acted = loop.act(Command.STAY, ticks=3)
        assert acted.ticks == 3 and loop.traces().time.size == 4
        assert loop.status() == LoopStatus(False, float(loop.world.speed[0]), 0, 0, 0, 0)
        result = loop.result(0)
        assert result.steps == 3 and result.lane_changes == loop.status().lane_changes


def test_a_scripted_lane_change_is_read_through_the_loops_face():
    """`start_lane_change` plans a change past the safety layer (None when the maneuver refuses
    it); `traces()` and `solve_statistics()` read what the loop recorded, as `drivestack track` does."""
    config = build_config({})
    loop = ClosedLoop(config, EmptyRoad("straight", "kinematic", 20.0, config.dt))
    loop.reset(0)
    assert loop.solve_statistics() == SolveStatistics(p50_ms=0.0, p95_ms=0.0, fallbacks=0)
    assert loop.start_lane_change(Command.STAY, at_time=1.0) is None
    assert loop.start_lane_change(Command.LEFT, at_time=1.0) == config.controller.lane_change_duration_s
    assert loop.start_lane_change(Command.RIGHT, at_time=2.0) is None, "a change is planned already"
    loop.act(Command.STAY, ticks=30)
    traces = loop.traces()
    assert loop.changing_lane and traces.time[-1] == pytest.approx(2.0)
    assert len(traces.time) == len(traces.d) == 31 and len(traces.d_reference) == len(traces.steering) == 30
    assert traces.d[-1] < traces.d[0], "moving towards the lane on the left"
    solves = loop.solve_statistics()
    assert solves.fallbacks == 0 and 0.0 < solves.p50_ms <= solves.p95_ms
    later = ClosedLoop(config, EmptyRoad("straight", "kinematic", 20.0, config.dt))
    later.reset(0)
    later.act(Command.STAY, ticks=15)
    assert later.start_lane_change(Command.LEFT, at_time=0.5) is None, "a start before now"
    assert not later.changing_lane and later.start_lane_change(Command.LEFT, at_time=1.5) is not None
