"""What a world allows (`stack.runs.world_allowance`): the lane law on constructed roads, and one
scenario's seeds read from the simulator, the same on every reset."""

import numpy as np
import pytest

from stack.apps.options import per_agent
from stack.runs.world_allowance import Cruise, lane_speeds, world_allowance
from stack.settings.run import in_scenario
from tests.helpers import LANE_WIDTH, scene

CRUISE = Cruise(set_speed=30.0, acceleration=2.0, time_gap=1.5, standstill_gap=8.0)
HORIZON_S = 40.0


def test_an_empty_lane_allows_the_set_speed_after_the_ego_accelerates_to_it():
    world = scene(2, (0.0, 0), speed=20.0)
    reach = 20.0 * 5.0 + 0.5 * 2.0 * 5.0**2 + 30.0 * 35.0
    assert lane_speeds(world, np.zeros(1), np.full(2, np.inf), HORIZON_S, CRUISE) == pytest.approx(
        [reach / HORIZON_S] * 2
    )


def test_a_slow_vehicle_ahead_holds_its_lane_down_and_one_behind_does_not():
    world = scene(2, (0.0, 0), [(105.0, 0.0), (-50.0, LANE_WIDTH)], speed=30.0)
    desired = np.array([0.0, 20.0, 5.0])
    speeds = lane_speeds(world, desired, np.full(2, np.inf), HORIZON_S, CRUISE)
    truck = (100.0 + 20.0 * HORIZON_S - (8.0 + 1.5 * 20.0)) / HORIZON_S
    assert speeds == pytest.approx([truck, 30.0])
    limited = lane_speeds(world, np.array([0.0, 35.0, 5.0]), np.array([25.0, 30.0]), HORIZON_S, CRUISE)
    assert limited[0] == pytest.approx((100.0 + 25.0 * HORIZON_S - (8.0 + 1.5 * 25.0)) / HORIZON_S)


def test_a_scenario_seed_allows_the_same_on_every_reset_and_its_fastest_lane_at_least_its_own():
    config = in_scenario(
        per_agent(None, [], [("keep-lane", None)], labels={}, model_option="--models")[0], "overtaking"
    )
    first = [world_allowance(config, seed) for seed in (1_007_000, 1_007_001)]
    assert [world_allowance(config, seed) for seed in (1_007_000, 1_007_001)] == first
    assert all(0.0 < a.own_lane <= a.allowed <= 30.0 for a in first)
    assert first[0].allowed - first[0].own_lane > 1.0
