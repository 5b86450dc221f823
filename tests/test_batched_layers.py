"""The layers' batched kernels against their per-world code, on worlds the closed loop drove: the
`observation` encoding (`perception.grid.observe_batch`) to the bits of `OccupancyGridBuilder
.build(world).encode("observation")`, and the safety layer's verdicts (`planner.safety.permitted_batch`)
to each loop's `permitted()`."""

import dataclasses

import numpy as np
import pytest

from perception.grid import OccupancyGridBuilder, observe_batch
from perception.sensor import SensorBatch, SensorConfig, SensorModel
from planner.agents import decide
from planner.lookahead_scene import lookahead_grid
from planner.safety import permitted_batch
from records import GridConfig, WorldState
from records.batch import WorldBatch
from stack.loop.closed_loop import ClosedLoop
from stack.runs.kept import build_agent
from stack.settings.run import build_config
from stack.sim.highway import HighwayAdapter

GRIDS = {
    "default": GridConfig(),
    "ego rows, every batched feature": GridConfig(
        lanes="ego",
        lateral_reach=2,
        features=("relative_speed", "ttc", "ego_speed", "ego_lateral"),
        lane_code="sides",
    ),
    "centre cells only": GridConfig(
        lanes="ego", footprint=False, features=("ttc", "relative_speed"), lane_code="sides", cell_length=3.0
    ),
    "the lookahead's": lookahead_grid(GridConfig()),
}


def driven_worlds(scenario: str, seeds: tuple[int, ...], every_s: float = 2.0) -> list[WorldState]:
    """What the sensor reported every `every_s` [s] of closed-loop episodes keeping the lane (the
    stack's cruise) on `scenario`: queues, the traffic's lane changes, trucks, incidents, noise."""
    config = build_config({"highway": {"duration": 6}}, scenario=scenario)
    worlds = []
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter)
        for seed in seeds:
            loop.reset(seed)
            next_time = 0.0
            while not loop.done:
                if loop.world.time >= next_time:
                    worlds.append(loop.perceived)
                    next_time += every_s
                loop.tick()
    return worlds


@pytest.fixture(scope="module")
def worlds() -> list[WorldState]:
    return (
        driven_worlds("random", (0, 4, 11, 1))
        + driven_worlds("incident", (0,))
        + driven_worlds("dense", (0,))
    )


def same_size_groups(worlds: list[WorldState], grid: GridConfig) -> list[list[WorldState]]:
    """The worlds in batches whose observations have one size (absolute rows: one lane count)."""
    if grid.lanes == "ego" and grid.lane_code == "sides":
        return [worlds]
    counts = sorted({world.lanes_count for world in worlds})
    return [[world for world in worlds if world.lanes_count == count] for count in counts]


@pytest.mark.parametrize("name", list(GRIDS))
def test_every_world_of_a_batch_is_encoded_to_the_per_world_bits(worlds, name):
    grid = GRIDS[name]
    builder = OccupancyGridBuilder(grid)
    for group in same_size_groups(worlds, grid):
        batched = observe_batch(grid, WorldBatch.of(group))
        for row, world in enumerate(group):
            alone = builder.build(world).encode("observation")
            assert batched.dtype == alone.dtype == np.float32
            np.testing.assert_array_equal(
                batched[row].view(np.uint32), alone.view(np.uint32), err_msg=f"world {row}"
            )
    assert {world.lanes_count for world in worlds} == {2, 3, 4, 5, 6}, "roads of every width"


def test_a_world_alone_and_in_any_batch_is_encoded_the_same(worlds):
    grid = GRIDS["ego rows, every batched feature"]
    whole = observe_batch(grid, WorldBatch.of(worlds))
    for start in (0, 5):
        part = observe_batch(grid, WorldBatch.of(worlds[start : start + 3]))
        np.testing.assert_array_equal(part, whole[start : start + 3])


def test_the_worlds_of_one_lane_count_taken_from_a_batch_are_encoded_as_a_batch_of_their_own(worlds):
    batch, grid = WorldBatch.of(worlds), GridConfig()
    for lanes in (3, 5):
        picked = np.flatnonzero(batch.lanes_count == lanes)
        alone = WorldBatch.of([worlds[k] for k in picked.tolist()])
        np.testing.assert_array_equal(observe_batch(grid, batch.rows(picked)), observe_batch(grid, alone))


def test_what_the_batch_cannot_encode_is_refused_in_one_line(worlds):
    batch = WorldBatch.of(worlds)
    with pytest.raises(
        ValueError, match="the batched grid computes relative_speed, ttc, ego_speed, ego_lateral, not traffic"
    ):
        observe_batch(GridConfig(lanes="ego", lane_code="sides", features=("traffic",)), batch)
    with pytest.raises(ValueError, match="need lanes: ego and lane_code: sides"):
        observe_batch(GridConfig(), batch)
    broken = dataclasses.replace(
        worlds[0], speed=np.where(np.arange(worlds[0].count) == 1, np.nan, worlds[0].speed)
    )
    with pytest.raises(ValueError, match="world 1 has a non-finite state"):
        observe_batch(GRIDS["ego rows, every batched feature"], WorldBatch.of([worlds[1], broken]))


@pytest.mark.parametrize("far_lane_gap_m", [None, 2.0, 12.0])
def test_the_safety_layer_s_verdicts_for_a_batch_are_each_loop_s(far_lane_gap_m: float | None):
    """At every decision period of MOBIL-driven episodes, stepped as the training MDP steps them
    (so also while a change runs; refusals, noise): `permitted_batch` over all of them equals each
    loop's `permitted()`, with and without the check of the lane beyond the target."""
    expected, perceived, lanes, changing, speeds = [], [], [], [], []
    planner = {"agent": "mobil", "safety": {"far_lane_gap_m": far_lane_gap_m}}
    for scenario, seeds in (("random", (0, 11)), ("jam", (0,)), ("incident", (1,))):
        config = build_config({"highway": {"duration": 10}, "planner": planner}, scenario=scenario)
        agent = build_agent(config, 0)
        with HighwayAdapter(config.highway, config.sim.backend) as adapter:
            loop = ClosedLoop(config, adapter, grid=agent.grid_config)
            for seed in seeds:
                loop.reset(seed)
                while not loop.done:
                    expected.append(loop.permitted())
                    perceived.append(loop.perceived)
                    lanes.append(loop.maneuver.lane)
                    changing.append(loop.maneuver.changing_lane)
                    speeds.append(float(loop.world.speed[0]))
                    command = decide(agent, loop.observation(loop.perceive(), agent.encoding, False))
                    loop.act(command, ticks=config.decision_ticks)
    safety, min_speed = config.planner.safety, loop.maneuver.min_speed
    batched = permitted_batch(
        safety, WorldBatch.of(perceived), np.array(lanes), np.array(changing), np.array(speeds), min_speed
    )
    np.testing.assert_array_equal(batched, np.array(expected))
    refused = (batched[:, [0, 2]] == 0) & ~np.array(changing)[:, None]
    assert refused.any() and (batched[:, [0, 2]] == 1).any() and any(changing), "every verdict occurs"


SENSORS = {
    "noisy's": SensorConfig(position_noise_m=0.5, miss_probability=0.05, false_positives=0.2),
    "poor, short range": SensorConfig(
        range_m=60.0, position_noise_m=2.0, miss_probability=0.4, false_positives=3.0
    ),
    "phantoms only": SensorConfig(false_positives=1.5, false_positive_range_m=100.0),
    "perfect": SensorConfig(),
}


def assert_reported(sensed: WorldBatch, reported: list[WorldState]) -> None:
    expected = WorldBatch.of(reported)
    np.testing.assert_array_equal(sensed.count, expected.count)
    for name in ("s", "d", "speed", "heading", "length", "width", "lane"):
        for k, n in enumerate(expected.count.tolist()):
            np.testing.assert_array_equal(getattr(sensed, name)[k, :n], getattr(expected, name)[k, :n], name)


@pytest.mark.parametrize("sensor", SENSORS.values(), ids=SENSORS.keys())
def test_batched_sensor_reports_what_each_world_s_sensor_model_reports(worlds, sensor):
    """Every world observed, then every other one (the rest keep their last report)."""
    alone = [SensorModel(sensor, seed) for seed in range(len(worlds))]
    together = SensorBatch(len(worlds))
    for seed in range(len(worlds)):
        together.reset_world(seed, SensorModel(sensor, seed))
    truth = WorldBatch.of(worlds)
    reported = [model.observe(world) for model, world in zip(alone, worlds, strict=True)]
    assert_reported(together.sense(truth, np.ones(len(worlds), dtype=bool)).batch, reported)
    odd = np.arange(len(worlds)) % 2 == 1
    reported = [alone[k].observe(world) if odd[k] else reported[k] for k, world in enumerate(worlds)]
    sensed = together.sense(truth, odd).batch
    assert_reported(sensed, reported)
    assert (sensed.count != truth.count).any() == sensor.enabled


def test_batched_sensor_reports_worlds_with_and_without_a_sensor_model_side_by_side(worlds):
    configs = [SENSORS["poor, short range"] if k % 2 else SENSORS["perfect"] for k in range(len(worlds))]
    alone = [SensorModel(config, seed) for seed, config in enumerate(configs)]
    together = SensorBatch(len(worlds))
    for seed, config in enumerate(configs):
        together.reset_world(seed, SensorModel(config, seed))
    truth = WorldBatch.of(worlds)
    for _ in range(3):
        reported = [model.observe(world) for model, world in zip(alone, worlds, strict=True)]
        sensed = together.sense(truth, np.ones(len(worlds), dtype=bool)).batch
        assert_reported(sensed, reported)
    np.testing.assert_array_equal(sensed.count[::2], truth.count[::2])
    assert (sensed.count[1::2] != truth.count[1::2]).any()
