"""The closed loop's shortcuts (issue 35) give exactly what the long way gives: the adapter's step
without reward and observation, the snapshot's kept lane offsets, the neighbours of every lane found
at once, the collision pairs, and the env and agent a worker keeps between episodes."""

import dataclasses

import numpy as np
import pytest

from common.neighbours import neighbours, scanned_neighbours
from records import Actuation
from stack.results.episode_result import TIMING_FIELDS
from stack.runs import kept
from stack.runs.episodes import run_episode
from stack.settings.run import HighwayConfig, build_config
from stack.sim.fast_road import FastRoad
from stack.sim.highway import HighwayAdapter, snapshot
from tests.helpers import scene


def test_the_snapshot_from_the_moved_frame_is_the_snapshot_from_the_vehicles():
    """After a vector step the adapter reads the vehicles' state from the arrays the step computed:
    every field of every frame is the bits of the snapshot read off the vehicles, crashes and all."""
    adapter = HighwayAdapter(build_config({}, scenario="dense").highway.model_copy(update={"duration": 10}))
    adapter.reset(seed=1)
    env, taken = adapter.road_env, []
    take_moved = env.road.take_moved
    env.road.take_moved = lambda: taken.append(take_moved()) or taken[-1]
    for frame in range(150):
        stepped = adapter.step(Actuation(5.0, 0.0))
        assert taken[-1] is not None and taken[-1].vehicles == env.road.vehicles
        read = snapshot(env.road, env.vehicle, float(env.time), adapter.config.lanes_count)
        for field in dataclasses.fields(stepped):
            a, b = getattr(stepped, field.name), getattr(read, field.name)
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype and a.shape == b.shape, field.name
                np.testing.assert_array_equal(
                    a.view(np.uint8), b.view(np.uint8), err_msg=f"{field.name} {frame}"
                )
            else:
                assert a == b, field.name
        if adapter.done:
            break
    assert stepped.crashed.any()
    assert len(taken) == frame + 1


def test_the_adapter_step_leaves_the_road_as_env_step_does():
    fast, full = (HighwayAdapter(HighwayConfig(vehicles_count=30, duration=4)) for _ in range(2))
    fast.reset(seed=5)
    full.reset(seed=5)
    full.renders = True  # the adapter then goes through env.step, as when it renders
    for frame in range(60):
        actuation = Actuation(1.5, 0.03 * np.sin(frame / 7))
        a, b = fast.step(actuation), full.step(actuation)
        for name in ("position", "heading", "speed", "lane", "s", "d", "crashed", "lane_offsets"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=f"{name} {frame}")
        assert (a.time, fast.terminated, fast.truncated) == (b.time, full.terminated, full.truncated)
        if fast.done:
            break
    assert fast.done


@pytest.mark.parametrize("seed", range(6))
def test_the_neighbours_of_every_lane_at_once_are_each_lane_s(seed):
    rng = np.random.default_rng(seed)
    others = [(float(rng.uniform(-40, 40)), float(rng.uniform(-3, 15))) for _ in range(rng.integers(0, 25))]
    others += others[:3]  # ties in distance
    world = scene(4, (0.0, int(rng.integers(0, 4))), others, length=float(rng.uniform(4, 12)))
    for lane in range(-4, 4):
        assert neighbours(world, lane) == scanned_neighbours(world, lane)
    with pytest.raises(IndexError):
        neighbours(world, 4)


def test_the_neighbours_with_a_vehicle_at_infinity_are_each_lane_s():
    world = scene(3, (0.0, 1), [(np.inf, 4.0), (np.inf, 0.0), (-np.inf, 4.0), (12.0, 8.0)])
    for lane in range(3):
        assert neighbours(world, lane) == scanned_neighbours(world, lane)


@pytest.mark.parametrize("seed", range(3))
def test_collision_pairs_are_the_stock_loop_s_candidates(seed):
    adapter = HighwayAdapter(HighwayConfig(vehicles_count=60, vehicles_density=2.5), backend="fast")
    adapter.reset(seed=seed)
    road = adapter.env.unwrapped.road
    assert isinstance(road, FastRoad)
    for _ in range(20):
        adapter.step(Actuation(2.0, 0.0))
        vehicles, dt = road.vehicles, adapter.dt
        expected = [
            (i, j)
            for i, a in enumerate(vehicles)
            for j in range(i + 1, len(vehicles))
            if np.linalg.norm(vehicles[j].position - a.position)
            <= (a.diagonal + vehicles[j].diagonal) / 2 + a.speed * dt + 1e-6
        ]
        assert [tuple(pair) for pair in road._collision_pairs(dt).tolist()] == expected


def _record(result) -> dict:
    return {
        f.name: getattr(result, f.name)
        for f in dataclasses.fields(result)
        if f.name not in ("snapshot", *TIMING_FIELDS)
    }


@pytest.mark.parametrize("agent", ["ddqn", "mobil"])
def test_an_episode_s_result_does_not_depend_on_what_its_process_ran_before(agent):
    config = build_config(
        {"planner": {"agent": agent}, "seed": 3}, scenario="overtaking", highway__duration=4
    )
    other = build_config({"planner": {"agent": agent}, "seed": 8}, scenario="dense", highway__duration=3)
    kept._adapters.clear()
    kept._agents.clear()
    fresh = [_record(run_episode(config, episode)) for episode in (0, 1)]
    assert len(kept._adapters) == 1
    run_episode(other, 0)
    assert [_record(run_episode(config, episode)) for episode in (1, 0)] == fresh[::-1]
    assert len(kept._adapters) == 2
    assert len(kept._agents) == (2 if agent == "ddqn" else 0)


def test_a_process_keeps_a_bounded_number_of_envs():
    kept._adapters.clear()
    for vehicles in range(kept.KEPT_PER_PROCESS + 2):
        config = build_config({"planner": {"agent": "keep-lane"}}, highway__vehicles_count=5 + vehicles)
        assert kept.kept_adapter(config) is kept.kept_adapter(config)
    assert len(kept._adapters) == kept.KEPT_PER_PROCESS


def test_what_a_snapshot_derived_stays_out_of_its_fields():
    world = scene(3, (0.0, 1), [(10.0, 4.0), (-8.0, 0.0)])
    ahead = neighbours(world, 1)[0]
    world.ego_state()
    moved = type(world)(**{**world.__dict__, "s": world.s + np.array([0.0, 5.0, 0.0])})
    assert set(world.__dict__) == {f.name for f in dataclasses.fields(world)}
    assert neighbours(moved, 1)[0].gap == ahead.gap + 5.0
