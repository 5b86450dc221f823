"""The lookahead agent: its grid read back into vehicles, its rollout physics, the safety layer's
gaps, hysteresis, determinism, and a closed-loop run."""

from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from perception.grid import OccupancyGridBuilder
from planner.factory import make_agent
from planner.lookahead import LookaheadAgent, LookaheadSetup
from planner.lookahead_config import LookaheadConfig
from planner.lookahead_scene import Scene, read_scene
from planner.safety import SafetyConfig, SafetyLayer
from records import Command, GridConfig
from stack.apps.cli import app
from tests.helpers import LANE_WIDTH
from tests.helpers import scene as world_scene

AGENT = LookaheadAgent(GridConfig())


def scene(vehicles=(), speed=25.0, left=True, right=True):
    """A `Scene` of (lane shift, centre [m], length [m], speed [m/s]) vehicles, with `left` and
    `right` lanes beside the ego (a bool: one or none). The counts are ints, as `read_scene` gives
    them: the compiled ranking then has one signature, the one `tests.kernel_warmup` compiles."""
    lane, centre, length, velocity = (
        (np.array(column, dtype=float) for column in zip(*vehicles, strict=True))
        if vehicles
        else (np.zeros(0),) * 4
    )
    return Scene(speed, int(left), int(right), lane.astype(np.int64), centre, length, velocity)


def test_a_stopped_car_ahead_sends_the_ego_into_the_free_left_lane():
    ranking = AGENT.rank(scene([(0, 120.0, 5.0, 0.0)]))
    scores = dict(zip(ranking.commands, ranking.scores, strict=True))
    assert ranking.chosen is Command.LEFT
    assert scores[Command.STAY] < scores[Command.LEFT] - 0.05


def test_without_a_left_lane_it_goes_right_and_never_off_the_road():
    ranking = AGENT.rank(scene([(0, 120.0, 5.0, 0.0)], left=False))
    assert Command.LEFT not in ranking.commands and ranking.chosen is Command.RIGHT
    alone = AGENT.rank(scene([(0, 120.0, 5.0, 0.0)], left=False, right=False))
    assert alone.commands == (Command.STAY,) and alone.chosen is Command.STAY


def test_a_lane_the_safety_layer_would_refuse_is_never_rolled_out():
    beside = scene([(0, 120.0, 5.0, 0.0), (-1, 2.0, 5.0, 25.0)], right=False)
    assert AGENT.permitted(beside) == (Command.STAY,)
    fast_from_behind = scene([(0, 120.0, 5.0, 0.0), (-1, -40.0, 5.0, 40.0)], right=False)
    assert Command.LEFT not in AGENT.permitted(fast_from_behind)
    assert AGENT.rank(fast_from_behind).chosen is Command.STAY
    beside_beyond = scene([(0, 120.0, 5.0, 0.0), (-2, -1.0, 5.0, 25.0)], right=False)
    assert AGENT.permitted(beside_beyond) == (Command.STAY,), "a car alongside in the lane beyond"
    assert AGENT.permitted(scene([(0, 120.0, 5.0, 0.0), (-2, -12.0, 5.0, 25.0)], right=False)) == (
        Command.STAY,
        Command.LEFT,
    )


def test_a_car_stopped_ahead_in_the_left_lane_scores_the_change_into_it_lower():
    ranking = AGENT.rank(scene([(0, 150.0, 5.0, 10.0), (-1, 110.0, 5.0, 0.0)], right=False))
    scores = dict(zip(ranking.commands, ranking.scores, strict=True))
    assert ranking.chosen is Command.STAY and scores[Command.LEFT] < scores[Command.STAY]


def test_a_change_towards_a_fast_lane_two_over_is_worth_its_first_step():
    trucks = [(0, 30.0, 12.0, 18.0), (-1, 45.0, 12.0, 17.0), (-2, 80.0, 5.0, 30.0)]
    blocked = scene(trucks, speed=18.0, left=2, right=0)
    onward = LookaheadSetup(LookaheadConfig(terminal_s=4.0))
    assert LookaheadAgent(GridConfig(), onward).rank(blocked).chosen is Command.LEFT
    myopic = LookaheadSetup(LookaheadConfig(terminal_s=0.0))
    assert LookaheadAgent(GridConfig(), myopic).rank(blocked).chosen is Command.STAY


def test_hysteresis_keeps_the_lane_on_ties_and_near_ties():
    assert AGENT.rank(scene()).chosen is Command.STAY
    near = scene([(0, 100.0, 5.0, 24.5)])
    ranking = AGENT.rank(near)
    gain = max(ranking.scores) - ranking.scores[0]
    assert 0 < gain < AGENT.setup.config.margin and ranking.chosen is Command.STAY
    eager = LookaheadAgent(GridConfig(), LookaheadSetup(LookaheadConfig(margin=0.0)))
    assert eager.rank(near).chosen is not Command.STAY


def world_of(others, speed=25.0, lanes=3, ego_lane=1):
    """A straight road with the ego in `ego_lane` and (x [m], lane, speed [m/s]) others."""
    world = world_scene(
        lanes, (0.0, ego_lane), [(x, lane * LANE_WIDTH) for x, lane, _ in others], speed=speed
    )
    speeds = np.array([speed] + [v for _, _, v in others], dtype=float)
    return replace(world, speed=speeds, velocity=np.stack([speeds, np.zeros_like(speeds)], axis=1))


def observe(world):
    return OccupancyGridBuilder(AGENT.grid_config).build(world).encode("observation")


def test_the_grid_reads_back_into_the_vehicles_within_a_cell():
    world = world_of([(50.0, 1, 20.0), (-20.0, 0, 30.0), (8.0, 2, 25.0)])
    observation = observe(world)
    seen = read_scene(AGENT.grid_config, observation)
    assert seen.speed == pytest.approx(25.0, abs=1e-4) and seen.left and seen.right
    order = np.argsort(seen.lane)
    assert seen.lane[order].tolist() == [-1, 0, 1]
    assert seen.centre[order] == pytest.approx([-20.0, 50.0, 8.0], abs=1.0)
    assert seen.velocity[order] == pytest.approx([30.0, 20.0, 25.0], abs=1e-3)
    assert np.all(seen.length >= 5.0) and np.all(seen.length <= 5.0 + 2 * AGENT.grid_config.cell_length)
    with pytest.raises(ValueError, match="lookahead agent expected"):
        read_scene(AGENT.grid_config, observation[:-1])


def test_every_change_it_rolls_out_passes_the_safety_layer():
    rng = np.random.default_rng(0)
    layer = SafetyLayer(SafetyConfig())
    checked = 0
    for _ in range(300):
        others = [(rng.uniform(-60, 120), int(rng.integers(0, 3)), rng.uniform(0, 35)) for _ in range(6)]
        world = world_of(others, speed=rng.uniform(5, 35))
        permitted = AGENT.permitted(read_scene(AGENT.grid_config, observe(world)))
        for command in set(permitted) - {Command.STAY}:
            checked += 1
            assert layer.permits(command, world, 1), (command, others)
    assert checked > 30


def test_a_decision_is_deterministic():
    observation_scene = scene([(0, 70.0, 5.0, 15.0), (-1, 30.0, 12.0, 20.0), (1, -30.0, 5.0, 28.0)])
    first = AGENT.rank(observation_scene)
    again = make_agent("lookahead", 4, GridConfig()).rank(observation_scene)
    assert first.chosen is again.chosen and np.array_equal(first.scores, again.scores)


def test_lookahead_drives_a_closed_loop_episode_from_the_cli(tmp_path):
    out = tmp_path / "run"
    result = CliRunner().invoke(
        app,
        ["run", "--agent", "lookahead", "--episodes", "1", "--scenario", "noisy", "--set",
         "highway.duration=4", "--out", str(out), "--no-progress"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert (out / "summary.json").is_file()
