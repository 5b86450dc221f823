import math

import numpy as np
import pytest

from records import Actuation
from stack.settings.run import HighwayConfig
from stack.sim.highway import HighwayAdapter, to_env_action


@pytest.fixture
def adapter():
    adapter = HighwayAdapter(HighwayConfig(vehicles_count=20, duration=5))
    yield adapter
    adapter.close()


def test_env_runs_one_frame_per_step_with_continuous_action(adapter):
    env = adapter.env.unwrapped
    assert env.config["action"]["type"] == "ContinuousAction"
    assert env.config["policy_frequency"] == env.config["simulation_frequency"] == 15
    world = adapter.reset(seed=1)
    after = adapter.step(Actuation(0.0, 0.0))
    assert after.time - world.time == pytest.approx(1 / 15)


def test_snapshot_matches_the_env_vehicles(adapter):
    world = adapter.reset(seed=2)
    for _ in range(10):
        world = adapter.step(Actuation(0.5, 0.01))
    road = adapter.env.unwrapped.road
    ego = adapter.env.unwrapped.vehicle
    assert world.count == len(road.vehicles)
    assert world.ids[0] == road.vehicles.index(ego)
    for row in range(world.count):
        vehicle = road.vehicles[world.ids[row]]
        np.testing.assert_array_equal(world.position[row], vehicle.position)
        assert world.heading[row] == vehicle.heading
        assert world.speed[row] == vehicle.speed
        np.testing.assert_allclose(world.velocity[row], vehicle.velocity, atol=1e-12)
        assert world.lane[row] == vehicle.lane_index[2]
        assert (world.length[row], world.width[row]) == (vehicle.LENGTH, vehicle.WIDTH)
        s, d = world.lanes[0].local_coordinates(vehicle.position)
        assert (world.s[row], world.d[row]) == pytest.approx((s, d), abs=1e-9)
    np.testing.assert_allclose(world.lane_offsets, [0, 4, 8, 12])
    assert world.ego_lane == ego.lane_index[2]


def test_actuation_maps_to_highway_env_action_range():
    np.testing.assert_allclose(to_env_action(Actuation(2.5, math.pi / 8)), [0.5, 0.5])
    np.testing.assert_allclose(to_env_action(Actuation(-50.0, -3.0)), [-1.0, -1.0])


def test_one_step_follows_the_kinematic_bicycle(adapter):
    world = adapter.reset(seed=3)
    steering, acceleration, dt = 0.1, 1.0, 1 / 15
    after = adapter.step(Actuation(acceleration, steering))
    beta = math.atan(0.5 * math.tan(steering))
    v, psi = world.speed[0], world.heading[0]
    assert after.position[0, 0] == pytest.approx(world.position[0, 0] + v * math.cos(psi + beta) * dt)
    assert after.position[0, 1] == pytest.approx(world.position[0, 1] + v * math.sin(psi + beta) * dt)
    assert after.heading[0] == pytest.approx(psi + v * math.sin(beta) / 2.5 * dt)
    assert after.speed[0] == pytest.approx(v + acceleration * dt)


def test_rendering_draws_the_road():
    with HighwayAdapter(HighwayConfig(vehicles_count=5, duration=1), render=True) as adapter:
        adapter.reset(seed=0)
        frame = adapter.render()
    assert frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 10, "a blank frame: highway-env skipped drawing"
