"""Each world of a `TrafficBatch` is the world the `vector` backend drives alone through
`HighwayAdapter`: every vehicle's x, y, heading, speed, lane, target lane and crash flag, at every
frame, bit for bit, across crashes and the autoreset that follows them; for any batch size."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from highway_env.road.lane import StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle

from records import Actuation
from records.batch import WorldBatch
from stack.settings.run import build_config
from stack.settings.world import HighwayConfig
from stack.sim.batch.arrays import BatchArrays
from stack.sim.batch.through_road import read_through_road, through_segments
from stack.sim.batch.traffic import TrafficBatch
from stack.sim.batch.traffic_frame import lane_frame
from stack.sim.batch.traffic_kernels import lane_neighbours
from stack.sim.batch.world_reading import UnsupportedRoad, read_world
from stack.sim.envs import FAST_EXIT, HIGHWAY
from stack.sim.highway import HighwayAdapter, env_config


def rams(frame: int, world: int) -> tuple[float, float]:
    """An ego that speeds up and weaves (world by world a little differently): it rear-ends traffic
    in some worlds, so crashes, impacts and autoresets are compared too."""
    return 2.0 + 2.0 * np.sin(frame / 9 + world), 0.03 * np.sin(frame / 15 + 2 * world)


def vehicle_states(vehicles: list) -> np.ndarray:
    """x, y, heading, speed, lane id, target lane id and crash flag of highway-env vehicles."""
    rows = []
    for v in vehicles:
        target = getattr(v, "target_lane_index", v.lane_index)
        rows.append([*v.position, v.heading, v.speed, v.lane_index[2], target[2], v.crashed])
    return np.array(rows, dtype=float)


def world_states(batch: TrafficBatch, world: int) -> np.ndarray:
    """The same columns of one world of a batch (lane rows are lane ids on highway-v0's roads)."""
    arrays = batch.arrays
    n = arrays.count[world]
    columns = [
        arrays.x,
        arrays.y,
        arrays.heading,
        arrays.speed,
        arrays.lane,
        arrays.target_lane,
        arrays.crashed,
    ]
    return np.stack([column[world, :n] for column in columns], axis=1).astype(float)


def batch_trajectories(highway: HighwayConfig, seeds: list[int], frames: int) -> list[list[np.ndarray]]:
    """Every world's states after reset and after each of `frames` steps, world k seeded `seeds[k]`."""
    batch = TrafficBatch(highway, len(seeds))
    batch.reset(seeds)
    trajectories = [[world_states(batch, k)] for k in range(len(seeds))]
    for frame in range(frames):
        actuations = np.array([rams(frame, k) for k in range(len(seeds))])
        batch.step(actuations[:, 0], actuations[:, 1])
        for k, trajectory in enumerate(trajectories):
            trajectory.append(world_states(batch, k))
    batch.close()
    return trajectories


def alone_trajectory(
    highway: HighwayConfig, seed: int, world: int, frames: int
) -> tuple[list[np.ndarray], int]:
    """The vector backend's states of world `world` driven alone, reset with `seed` and afterwards,
    once an episode ends, with `env.reset()` (its generator continued) at the next step, as the
    batch autoresets; and how many resets that took."""
    adapter = HighwayAdapter(highway, backend="vector")
    adapter.reset(seed)
    road = adapter.env.unwrapped
    states, resets = [vehicle_states(road.road.vehicles)], 0
    for frame in range(frames):
        if adapter.done:
            adapter.env.reset()
            adapter.terminated = adapter.truncated = False
            resets += 1
        else:
            acceleration, steering = rams(frame, world)
            adapter.step(Actuation(acceleration=acceleration, steering=steering))
        states.append(vehicle_states(road.road.vehicles))
    adapter.close()
    return states, resets


def assert_worlds_identical(highway: HighwayConfig, seeds: list[int], frames: int) -> int:
    """Compare every world of a batch with the vector backend alone; returns the autoresets seen."""
    resets = 0
    for k, batched in enumerate(batch_trajectories(highway, seeds, frames)):
        alone, world_resets = alone_trajectory(highway, seeds[k], k, frames)
        resets += world_resets
        for frame, (a, b) in enumerate(zip(alone, batched, strict=True)):
            np.testing.assert_array_equal(
                b.view(np.uint64), a.view(np.uint64), err_msg=f"world {k} (seed {seeds[k]}), frame {frame}"
            )
    return resets


@pytest.mark.parametrize(
    ("scenario", "frames"), [("highway-v0", 200), ("overtaking", 120), ("incident", 120), ("exit", 300)]
)
def test_each_world_is_the_vector_backends_world_bit_for_bit(scenario, frames):
    highway = build_config({}, scenario=scenario).highway
    resets = assert_worlds_identical(highway, [3, 0, 5], frames)
    if scenario == "highway-v0":
        assert resets >= 1, "the ramming ego of world 1 (seed 0) must crash, and its world autoreset"


STRAIGHT_SCENARIOS = ["highway-v0", "lanes-3", "lanes-5", "dense", "jam", "incident", "overtaking", "random"]


@pytest.mark.slow
@pytest.mark.parametrize("scenario", STRAIGHT_SCENARIOS)
def test_each_world_is_the_vector_backends_world_over_full_episodes(scenario):
    """Every named scenario on straight roads (`noisy` is `overtaking`'s world), three seeds, 40 s
    episodes and beyond: 660 frames with autoresets."""
    highway = build_config({}, scenario=scenario).highway
    assert_worlds_identical(highway, [0, 1, 2], frames=660)


def test_a_world_is_the_same_in_a_batch_of_any_size():
    highway = build_config({}, scenario="random").highway
    seeds = list(range(100, 164))
    wide = batch_trajectories(highway, seeds, frames=60)
    for size in (1, 3):
        for k, narrow in enumerate(batch_trajectories(highway, seeds[:size], frames=60)):
            for frame, (a, b) in enumerate(zip(wide[k], narrow, strict=True)):
                np.testing.assert_array_equal(
                    b.view(np.uint64), a.view(np.uint64), err_msg=f"N={size}, {frame}"
                )


def test_the_road_of_a_world_steps_on_in_highway_env_as_in_the_batch():
    """`road(world)` builds highway-env objects that stock `Road.act` and `Road.step` take to the
    batch's next frame exactly."""
    highway = build_config({}, scenario="overtaking").highway
    batch = TrafficBatch(highway, 2)
    batch.reset([7, 8])
    for _ in range(30):
        batch.step(np.array([1.0, -1.0]), np.array([0.0, 0.01]))
    vehicles, ego = batch.road(1)
    assert np.array_equal(vehicle_states(vehicles), world_states(batch, 1))
    road = vehicles[0].road
    assert isinstance(road, Road)
    batch.step(np.array([1.0, -1.0]), np.array([0.0, 0.01]))
    arrays, driven = batch.arrays, batch.arrays.ego[1]
    ego.action = {"acceleration": arrays.acceleration[1, driven], "steering": arrays.steering[1, driven]}
    road.act()
    road.step(batch.dt)
    np.testing.assert_array_equal(vehicle_states(road.vehicles), world_states(batch, 1))


def test_roads_the_batch_cannot_hold_are_refused_by_name():
    env = gym.make("exit-v0", config={}, disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(UnsupportedRoad, match="one segment"):
        read_world(env.unwrapped.road, env.unwrapped.vehicle)
    env.close()
    env = gym.make(HIGHWAY, config=env_config(HighwayConfig(vehicles_count=3)), disable_env_checker=True)
    env.reset(seed=0)
    env.unwrapped.road.vehicles[1].route = [("0", "1", 0)]
    with pytest.raises(UnsupportedRoad, match="routes"):
        read_world(env.unwrapped.road, env.unwrapped.vehicle)


def test_the_neighbour_search_picks_highway_envs_neighbours_on_ties():
    """`lane_neighbours` against `Road.neighbour_vehicles` for every vehicle on every lane of crowded
    random roads whose positions tie in s (the last front in road order, the first rear), including
    vehicles between lanes and beyond the road's ends."""
    rng = np.random.default_rng(11)
    compared = 0
    for _ in range(30):
        road = Road(RoadNetwork.straight_road_network(3, length=200), np_random=np.random.default_rng(0))
        for _ in range(int(rng.integers(2, 25))):
            position = [np.round(rng.uniform(-10, 215) * 2) / 2, np.round(rng.uniform(-3, 11) * 4) / 4]
            road.vehicles.append(Vehicle(road, position, 0.0, 20.0))
        arrays = BatchArrays(1)
        arrays.load(0, read_world(road, road.vehicles[0]))
        s, _, on, on_count = lane_frame(arrays, arrays.count)
        for lane in range(3):
            rows = np.arange(len(road.vehicles))
            front, rear = lane_neighbours(
                rows, np.full(len(rows), lane), s, on, on_count, np.zeros(len(rows), dtype=np.int64),
                arrays.segment_start, arrays.segment_length, StraightLane.VEHICLE_LENGTH,
            )  # fmt: skip
            for i, vehicle in enumerate(road.vehicles):
                expected = road.neighbour_vehicles(vehicle, ("0", "1", lane))
                got = tuple(road.vehicles[k] if k >= 0 else None for k in (front[i], rear[i]))
                assert got[0] is expected[0] and got[1] is expected[1], (lane, i)
                compared += 1
    assert compared > 500


def test_a_step_needs_reset_worlds_and_one_actuation_per_world():
    batch = TrafficBatch(HighwayConfig(vehicles_count=5), 2)
    with pytest.raises(ValueError, match=r"worlds \[0, 1\] have not been reset"):
        batch.step(np.zeros(2), np.zeros(2))
    batch.reset([0, 1])
    with pytest.raises(ValueError, match=r"2 worlds, got shape \(3,\)"):
        batch.step(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="one seed per world"):
        batch.reset([0])
    assert not batch.step([0.0, 0.0], [0.0, 0.0]).terminated.any()
    batch.close()


def test_stepping_only_some_worlds_leaves_the_others_as_they_are():
    highway = HighwayConfig(vehicles_count=8, duration=1)
    together, alone = TrafficBatch(highway, 2), TrafficBatch(highway, 1)
    together.reset([3, 4])
    alone.reset([3])
    frozen = world_states(together, 1)
    only, steps = np.array([True, False]), 0
    while steps < 20:
        ended = together.step([1.0, 1.0], [0.0, 0.0], only)
        steps += 1
        alone.step([1.0], [0.0])
        np.testing.assert_array_equal(world_states(together, 0), world_states(alone, 0))
        np.testing.assert_array_equal(world_states(together, 1), frozen)
        assert not ended.truncated[1]
        if ended.truncated[0]:
            break
    assert ended.truncated[0] and steps == 16
    with pytest.raises(ValueError, match=r"worlds \[0\] ended their episode"):
        together.step([0.0, 0.0], [0.0, 0.0], only)
    together.close()
    alone.close()


@pytest.mark.parametrize("scenario", ["overtaking", "random"])
def test_the_world_batch_is_the_adapters_snapshots_stacked(scenario):
    """`BatchArrays.world_batch()` (what the batched grid and safety layer read) against
    `WorldBatch.of` the vector backend's `HighwayAdapter` snapshots, world by world, frame by
    frame, bit for bit: the ego first, the others in road order, s and d in lane 0's frame."""
    highway = build_config({}, scenario=scenario).highway
    seeds = [3, 4, 5]
    batch = TrafficBatch(highway, len(seeds))
    batch.reset(seeds)
    adapters = [HighwayAdapter(highway, backend="vector") for _ in seeds]
    snapshots = [adapter.reset(seed) for adapter, seed in zip(adapters, seeds, strict=True)]
    for frame in range(60):
        batched = batch.arrays.world_batch()
        for k, snapshot in enumerate(snapshots):
            alone = WorldBatch.of([snapshot])
            n, lanes = alone.count[0], alone.lanes_count[0]
            assert (batched.count[k], batched.lanes_count[k]) == (n, lanes)
            for name in ("s", "d", "speed", "heading", "length", "width", "lane"):
                got, expected = getattr(batched, name)[k, :n], getattr(alone, name)[0]
                np.testing.assert_array_equal(got.view(np.uint64), expected.view(np.uint64), err_msg=name)
            np.testing.assert_array_equal(batched.lane_offsets[k, :lanes], alone.lane_offsets[0])
            assert batched.lane_heading[k] == alone.lane_heading[0]
            assert batched.lane_width == alone.lane_width
        pending = batch.ended.terminated | batch.ended.truncated
        actuations = np.array([rams(frame, k) for k in range(len(seeds))])
        batch.step(actuations[:, 0], actuations[:, 1])
        for k, adapter in enumerate(adapters):
            if pending[k]:
                adapter.env.reset()
                adapter.terminated = adapter.truncated = False
                snapshots[k] = adapter.snapshot()
            else:
                snapshots[k] = adapter.step(Actuation(*actuations[k]))


def test_the_exit_road_is_held_as_its_through_lanes_in_segments():
    """exit-v0's three straight segments chain into one through road of its six lanes (the exit
    lane and the curve left out), each segment kept by where it starts and how long it is; a
    vehicle on the exit lane is refused by name."""
    env = gym.make(
        FAST_EXIT, config=env_config(build_config({}, scenario="exit").highway), disable_env_checker=True
    )
    env.reset(seed=1022000)
    road = env.unwrapped.road
    assert through_segments(road.network, 6) == [("0", "1"), ("1", "2"), ("2", "3")]
    spawned = read_through_road(road, env.unwrapped.vehicle, 6)
    np.testing.assert_array_equal(spawned.segment_start, [0.0, 400.0, 500.0])
    np.testing.assert_array_equal(spawned.segment_length, [400.0, 100.0, 500.0])
    assert spawned.lanes.indices == [("0", "3", k) for k in range(6)]
    np.testing.assert_array_equal(spawned.lanes.speed_limit, [26 - 3.4 * k for k in range(6)])
    np.testing.assert_array_equal(spawned.lanes.length, np.full(6, 1000.0))
    assert spawned.columns["lane"].tolist() == [v.lane_index[2] for v in road.vehicles]
    road.vehicles[1].lane_index = ("1", "2", 6)
    with pytest.raises(UnsupportedRoad, match="through road's lanes, not lane"):
        read_through_road(road, env.unwrapped.vehicle, 6)
    env.close()
