"""Every episode starts drivable: on the stack's roads no vehicle, the ego included, spawns closer
to the one ahead in its lane than UN R157's minimum following distance at its speed (plus room to
slow to a slower leader's speed), on every named scenario, every backend and the batched worlds
alike, deterministic per seed; an incident too close to leave the ego that room is refused."""

import gymnasium as gym
import numpy as np
import pytest
from typer.testing import CliRunner

from common.r157 import (
    LEADER_BRAKING_MPS2,
    START_BRAKING_MPS2,
    r157_min_following_distance,
    start_gap,
    start_room,
)
from records import WorldState
from stack.apps.cli import app
from stack.settings.run import build_config
from stack.settings.world import EGO_LENGTH_M
from stack.sim import envs
from stack.sim.batch.traffic import TrafficBatch
from stack.sim.highway import HighwayAdapter
from stack.sim.traffic import INCIDENT_LENGTH_M, cumulative_class_odds, random_traffic, uniform_choice
from stack.worlds.scenarios import names

FIRST_SEED = 990_000
"""Seeds of these tests; the reports' seeds (880000 on, 980000 on) are never tested on."""


def too_close(world: WorldState) -> list[tuple[int, float, float]]:
    """(row of the follower, its gap to the vehicle ahead in its lane [m], R157's d_min at its
    speed [m]) of every vehicle that starts inside d_min, bumper to bumper, along the lane frame."""
    found = []
    for lane in np.unique(world.lane):
        rows = np.flatnonzero(world.lane == lane)
        rows = rows[np.argsort(world.s[rows], kind="stable")]
        for follower, leader in zip(rows[:-1], rows[1:], strict=True):
            gap = world.s[leader] - world.s[follower] - (world.length[leader] + world.length[follower]) / 2
            d_min = r157_min_following_distance(float(world.speed[follower]))
            if gap < d_min - 1e-9:
                found.append((int(follower), float(gap), d_min))
    return found


def test_start_gap_is_r157_distance_plus_room_to_match_a_slower_leader():
    assert start_gap(25.0, 25.0) == pytest.approx(5.0 + 25.0 * 1.6)
    assert start_gap(25.0, 30.0) == pytest.approx(5.0 + 25.0 * 1.6), "a faster leader needs no more"
    assert start_gap(1.0, 1.0) == pytest.approx(5.0), "below 7.2 km/h the jam clearance alone"
    closing = 25.0 - 18.0
    following = 40.0 + closing * 1.0 + closing**2 / (2 * START_BRAKING_MPS2)
    assert start_gap(25.0, 18.0) == pytest.approx(5.0 + following)
    assert start_gap(25.0, 25.0, leader_heading_for=18.0) == pytest.approx(5.0 + following)
    stopping = 30.0**2 / (2 * START_BRAKING_MPS2) - 30.0**2 / (2 * LEADER_BRAKING_MPS2)
    assert start_gap(30.0, 30.0, leader_heading_for=29.0) == pytest.approx(5.0 + stopping), (
        "a leader braking from its spawn on: room to stop behind it"
    )
    assert start_room(25.0, 25.0, 5.0, 12.0) == pytest.approx(8.5 + 45.0)


def assert_no_start_inside_r157_distance(scenario: str, seeds: int) -> None:
    config = build_config({}, scenario=scenario)
    with HighwayAdapter(config.highway, "vector") as adapter:
        for seed in range(FIRST_SEED, FIRST_SEED + seeds):
            world = adapter.reset(seed)
            assert too_close(world) == [], f"{scenario}, seed {seed}"


@pytest.mark.parametrize("scenario", names())
def test_no_vehicle_starts_inside_r157_distance_of_its_leader(scenario):
    assert_no_start_inside_r157_distance(scenario, seeds=12)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", names())
def test_no_vehicle_starts_inside_r157_distance_over_many_seeds(scenario):
    assert_no_start_inside_r157_distance(scenario, seeds=300)


@pytest.mark.parametrize("scenario", ["highway-v0", "overtaking", "random", "exit"])
def test_the_ego_starts_with_room_to_match_its_leaders(scenario):
    """Closing in on a slower leader (or one heading for a lower speed), in its lane or a lane next
    to it (one it may change into at once), the ego starts at least `start_gap` behind it, so its
    first frames need no emergency braking."""
    config = build_config({}, scenario=scenario)
    with HighwayAdapter(config.highway, "vector") as adapter:
        for seed in range(FIRST_SEED, FIRST_SEED + 20):
            adapter.reset(seed)
            env = adapter.road_env
            ego = env.vehicle
            lane = env.road.network.get_lane(ego.lane_index)
            s_ego = lane.local_coordinates(ego.position)[0]
            for side in (-1, 0, 1):
                ahead = [
                    (s, other)
                    for other in env.road.vehicles
                    for s, d in [lane.local_coordinates(other.position)]
                    if other is not ego and s > s_ego and abs(d - side * lane.width) < lane.width / 2
                ]
                if not ahead:
                    continue
                s_leader, leader = min(ahead, key=lambda pair: pair[0])
                heading_for = getattr(leader, "target_speed", leader.speed)
                needed = start_room(ego.speed, leader.speed, ego.LENGTH, leader.LENGTH, heading_for)
                assert s_leader - s_ego >= needed - 1e-9, f"{scenario}, seed {seed}, lane {side:+d}"


@pytest.mark.parametrize("scenario", ["overtaking", "random"])
def test_batched_worlds_spawn_what_one_world_spawns(scenario):
    """The batched worlds (`TrafficBatch`) and one world alone (`HighwayAdapter`) spawn through
    the same rule: the same vehicles at the same places, the same seed the same start."""
    config = build_config({}, scenario=scenario)
    seeds = [FIRST_SEED + 3, FIRST_SEED + 4]
    batch = TrafficBatch(config.highway, len(seeds))
    try:
        batch.reset(seeds)
        with HighwayAdapter(config.highway, "vector") as adapter:
            for world, seed in enumerate(seeds):
                alone = adapter.reset(seed)
                count = int(batch.arrays.count[world])
                batched = np.stack([batch.arrays.x[world, :count], batch.arrays.y[world, :count]], axis=1)
                assert sorted(map(tuple, batched)) == sorted(map(tuple, alone.position))
                again = adapter.reset(seed)
                np.testing.assert_array_equal(again.position, alone.position)
    finally:
        batch.close()


def test_every_backend_spawns_the_same_drivable_start():
    for scenario in ("highway-v0", "exit"):
        config = build_config({}, scenario=scenario)
        positions = []
        for backend in ("vector", "fast", "stock"):
            with HighwayAdapter(config.highway, backend) as adapter:
                world = adapter.reset(FIRST_SEED)
                assert too_close(world) == [], (scenario, backend)
                positions.append(world.position)
        for other in positions[1:]:
            np.testing.assert_array_equal(other, positions[0])


def test_the_exit_id_alone_is_exit_v0_vehicle_for_vehicle():
    starts = []
    for name in ("exit-v0", envs.EXIT, envs.FAST_EXIT):
        env = gym.make(name, disable_env_checker=True)
        env.reset(seed=FIRST_SEED)
        starts.append([tuple(vehicle.position) for vehicle in env.unwrapped.road.vehicles])
        env.close()
    assert starts[1] == starts[0] and starts[2] == starts[0]


def test_a_random_world_puts_its_stopped_car_beyond_the_ego_start_room():
    config = build_config({}, scenario="random")
    assert config.highway.random_traffic is not None
    ranges = config.highway.random_traffic.model_dump()
    ranges["incident_probability"] = 1.0
    rng = np.random.default_rng(FIRST_SEED)
    for _ in range(200):
        traffic = random_traffic(rng, ranges)["traffic"]
        speed = traffic["spawn_speed_mps"]
        room = start_room(speed, 0.0, EGO_LENGTH_M, INCIDENT_LENGTH_M)
        assert traffic["incident"]["ahead_m"] >= room


def test_an_incident_too_close_for_a_drivable_start_is_refused_in_one_line(tmp_path):
    result = CliRunner().invoke(
        app,
        [
            "run",
            "--scenario",
            "incident",
            "--set",
            "highway.traffic.incident.ahead_m=20",
            "--episodes",
            "1",
            "--out",
            str(tmp_path / "out"),
            "--no-progress",
        ],
    )
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "incident.ahead_m" in lines[0] and "spawn_speed_mps" in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_spawning_draws_what_numpys_choice_draws():
    classes = [{"share": 0.7}, {"share": 0.2}, {"share": 0.1}]
    for seed in range(FIRST_SEED, FIRST_SEED + 200):
        ours, numpys = np.random.default_rng(seed), np.random.default_rng(seed)
        for items in (["0"], [0, 1], [3, 4, 5, 6, 7]):
            assert uniform_choice(ours, items) == numpys.choice(items)
        drawn = int(np.searchsorted(cumulative_class_odds(classes), ours.random(), side="right"))
        assert drawn == numpys.choice(3, p=np.array([0.7, 0.2, 0.1]))
        assert ours.random() == numpys.random()
