"""Named scenarios: listing, selection, validation of their keys, and the heterogeneous traffic."""

import numpy as np
import pytest
from typer.testing import CliRunner

from records import Actuation
from stack.apps.cli import app
from stack.results.episode_result import outcome
from stack.runs.episodes import run
from stack.settings.run import ConfigError, build_config
from stack.sim.highway import HighwayAdapter
from stack.worlds import scenarios

REQUIRED = {"highway-v0", "dense", "lanes-3", "lanes-5", "overtaking", "noisy"}


def test_the_suite_is_listed_one_line_each():
    result = CliRunner().invoke(app, ["scenarios"])
    assert result.exit_code == 0
    lines = result.output.strip().splitlines()
    assert {line.split()[0] for line in lines} >= REQUIRED
    assert len(lines) == len(scenarios.names())
    assert all(len(line.split(maxsplit=1)[1]) > 20 for line in lines), "every scenario says what it is"


def test_a_scenario_replaces_the_world_and_keeps_the_rest():
    base = {"planner": {"agent": "mobil"}, "highway": {"lanes_count": 7}, "perception": {"cells_ahead": 12}}
    config = build_config(base, scenario="noisy")
    assert config.scenario == "noisy"
    assert config.highway.lanes_count == 4 and config.highway.traffic is not None
    assert config.perception.sensor.position_noise_m == 0.5 and config.perception.cells_ahead == 12
    assert config.planner.agent == "mobil"
    assert build_config({"scenario": "lanes-5"}).highway.lanes_count == 5
    overridden = build_config(base, scenario="dense", highway__vehicles_count=20)
    assert (overridden.highway.vehicles_density, overridden.highway.vehicles_count) == (1.5, 20)
    assert build_config(base, scenario="overtaking").perception.sensor.position_noise_m == 0.0


def test_highway_v0_is_highway_envs_defaults():
    config = build_config({}, scenario="highway-v0").highway
    assert (config.lanes_count, config.vehicles_count, config.vehicles_density, config.duration) == (
        4,
        50,
        1.0,
        40,
    )
    assert config.traffic is None and config.ego_spacing == 2 and config.initial_lane_id is None


TRAFFIC = {
    "ego_position": 0.5,
    "classes": [
        {"name": "truck", "share": 0.3, "speed_mps": [16, 20], "length_m": [10, 12]},
        {"name": "car", "share": 0.7, "speed_mps": [21, 29]},
    ],
}
CAR_ONLY = {**TRAFFIC["classes"][1], "share": 1}


@pytest.mark.parametrize(
    ("change", "key", "expected"),
    [
        ({"classes": [{**TRAFFIC["classes"][0], "speed_mps": [-16, 20]}]}, "speed_mps", "must be positive"),
        ({"classes": [{**TRAFFIC["classes"][0], "share": -0.3}]}, "share", "greater than 0"),
        ({"classes": TRAFFIC["classes"][:1]}, "classes", "the shares must sum to 1, got 0.3"),
        ({"classes": [{**TRAFFIC["classes"][1], "speed_mps": [29, 21], "share": 1}]}, "speed_mps", "low <="),
        ({"ego_position": 1.5}, "ego_position", "less than or equal to 1"),
        ({"spawn_speed_mps": 0}, "spawn_speed_mps", "greater than 0"),
        ({"classes": [{**CAR_ONLY, "lanes": [0, 4]}]}, "lanes", "lanes of the road (0..3)"),
        ({"classes": [{**CAR_ONLY, "lanes": []}]}, "lanes", "at least 1 item"),
    ],
)
def test_bad_traffic_is_refused_in_one_line_naming_the_key(change, key, expected):
    with pytest.raises(ConfigError) as error:
        build_config({"highway": {"traffic": {**TRAFFIC, **change}}}, "x.yaml")
    message = str(error.value)
    assert message.startswith("x.yaml: highway") and "traffic." in message and key in message
    assert expected in message
    assert "\n" not in message


def test_unknown_scenario_and_lane_off_the_road_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="scenario: unknown scenario 'mars'; available: dense, "):
        build_config({}, scenario="mars")
    with pytest.raises(ConfigError, match="initial_lane_id: must be a lane of the road"):
        build_config({"highway": {"lanes_count": 3, "initial_lane_id": 3}})
    result = CliRunner().invoke(app, ["compare", "--scenario", "mars", "--out", str(tmp_path / "c")])
    assert result.exit_code == 2 and "unknown scenario 'mars'" in result.output
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("backend", ["fast", "stock"])
def test_overtaking_traffic_is_seeded_heterogeneous_and_around_the_ego(backend):
    config = build_config({}, scenario="overtaking")
    with HighwayAdapter(config.highway, backend) as adapter:
        world = adapter.reset(seed=4)
        again = adapter.reset(seed=4)
        road = adapter.env.unwrapped.road
        vehicles = [road.vehicles[row] for row in world.ids[1:]]
    np.testing.assert_array_equal(world.position, again.position)
    others = world.s[1:] - world.s[0]
    assert (others < 0).sum() == 30 and (others > 0).sum() == 30, "half the traffic starts behind the ego"
    speeds = np.array([v.target_speed for v in vehicles])
    lengths = world.length[1:]
    trucks = lengths >= 10
    assert 0 < trucks.sum() < len(lengths)
    assert np.all((speeds[trucks] >= 16) & (speeds[trucks] <= 20))
    assert np.all((speeds[~trucks] >= 23) & (speeds[~trucks] <= 31))
    assert set(world.lane[1:][trucks]) <= {2, 3} and world.lane[0] == 3, "trucks and the ego keep right"
    assert not any(v.enable_lane_change for v, truck in zip(vehicles, trucks, strict=True) if truck)
    assert np.all(world.speed == 18), "every vehicle spawns at the same speed"
    jam = np.array([v.DISTANCE_WANTED for v in vehicles])
    np.testing.assert_allclose(jam, 5.0 + lengths, err_msg="the IDM jam distance grows with the length")


def test_fast_and_stock_backends_drive_the_same_scenario_traffic():
    config = build_config({"episodes": 1, "highway": {"duration": 6}}, scenario="overtaking")
    with HighwayAdapter(config.highway, "fast") as fast, HighwayAdapter(config.highway, "stock") as stock:
        fast.reset(seed=9), stock.reset(seed=9)
        for _ in range(60):
            a, b = fast.step(Actuation(0.5, 0.0)), stock.step(Actuation(0.5, 0.0))
            np.testing.assert_array_equal(a.position, b.position)
            np.testing.assert_array_equal(a.speed, b.speed)


def test_exit_road_runs_closed_loop_and_its_grid_sees_across_segments():
    config = build_config({"episodes": 1, "planner": {"agent": "rule"}}, scenario="exit")
    assert config.highway.road == "exit"
    with HighwayAdapter(config.highway, "fast") as fast, HighwayAdapter(config.highway, "stock") as stock:
        worlds = []
        fast.reset(seed=1), stock.reset(seed=1)
        for _ in range(120):
            world, other = fast.step(Actuation(1.0, 0.0)), stock.step(Actuation(1.0, 0.0))
            np.testing.assert_array_equal(world.position, other.position)
            worlds.append(world)
    assert all(w.lanes_count == 6 for w in worlds), "the exit lane is not driven"
    lanes = {fast_world.lane[0] for fast_world in worlds}
    assert lanes == {0}
    segment_end = 400.0
    near = [w for w in worlds if segment_end - 60 < w.position[0, 0] < segment_end]
    assert near, "the ego reaches the end of the first segment"
    world = near[-1]
    beyond = world.position[1:, 0] > segment_end
    assert beyond.any(), "vehicles drive on the next segment"
    np.testing.assert_allclose(
        world.s[1:][beyond] - world.s[0], world.position[1:, 0][beyond] - world.position[0, 0]
    )
    summary = run(config, progress=False).summary
    assert summary["scenario"] == "exit" and summary["collisions"] == 0


def test_keys_the_road_cannot_use_are_refused():
    with pytest.raises(ConfigError, match="highway: traffic: the exit road spawns its own traffic"):
        build_config({"highway": {"road": "exit", "traffic": TRAFFIC}})
    with pytest.raises(ConfigError, match="the exit road always starts the ego in lane 0"):
        build_config({"highway": {"road": "exit", "initial_lane_id": 2}})
    with pytest.raises(
        ConfigError, match="highway.road: unknown road 'roundabout'; available: highway, exit"
    ):
        build_config({"highway": {"road": "roundabout"}})


def test_run_and_train_take_a_scenario_from_the_cli(tmp_path):
    import json

    run_out, train_out = tmp_path / "run", tmp_path / "train"
    ran = CliRunner().invoke(
        app,
        [
            "run",
            "--scenario",
            "exit",
            "--agent",
            "keep-lane",
            "--episodes",
            "1",
            "--set",
            "highway.duration=5",
            "--no-progress",
            "--out",
            str(run_out),
        ],
    )
    assert ran.exit_code == 0, ran.output
    assert json.loads((run_out / "summary.json").read_text())["scenario"] == "exit"
    small = ["--envs", "1", "--set", "train.members=1", "--set", "train.buffer_size=1000"]
    small += ["--set", "highway.duration=5"]
    small += ["--set", "train.validation.short_episodes=1", "--set", "train.validation.long_episodes=1"]
    small += ["--set", "train.demonstrations.episodes=2", "--set", "train.demonstrations.pretrain_steps=5"]
    trained = CliRunner().invoke(
        app,
        ["train", "--scenario", "lanes-3", "--steps", "20", *small, "--no-progress", "--out", str(train_out)],
    )
    assert trained.exit_code == 0, trained.output
    assert "scenario: lanes-3" in (train_out / "config.yaml").read_text()


def test_a_scenario_gives_the_same_summaries_on_one_or_two_processes():
    config = build_config(
        {"episodes": 2, "planner": {"agent": "mobil"}}, scenario="noisy", highway__duration=4
    )
    serial, parallel = run(config, progress=False, jobs=1), run(config, progress=False, jobs=2)
    assert outcome(serial.summary) == outcome(parallel.summary)
    assert [e.trace for e in serial.episodes] == [e.trace for e in parallel.episodes]


def test_random_traffic_draws_a_seeded_world_per_episode_from_its_ranges():
    config = build_config({}, scenario="random")
    assert config.highway.lane_counts == (2, 3, 4, 5, 6)
    ranges = config.highway.random_traffic
    assert ranges is not None
    lanes, trucks_changing, truck_lanes = set(), set(), set()
    with HighwayAdapter(config.highway, "vector") as adapter:
        for seed in range(40):
            world = adapter.reset(seed=seed)
            drawn = adapter.env.unwrapped.config
            lanes.add(world.lanes_count)
            assert world.lanes_count == drawn["lanes_count"]
            assert ranges.vehicles_density[0] <= drawn["vehicles_density"] <= ranges.vehicles_density[1]
            classes = {kind["name"]: kind for kind in drawn["traffic"]["classes"]}
            car = classes["car"]["speed_mps"]
            assert ranges.car_speed_mps[0] <= car[0] <= ranges.car_speed_mps[1]
            if "truck" in classes:
                truck = classes["truck"]
                trucks_changing.add(truck["changes_lane"])
                assert truck["speed_mps"][1] <= car[1] and truck["speed_mps"][0] >= 2.0
                if not truck["changes_lane"]:
                    kept = tuple(truck["lanes"])
                    right = (world.lanes_count - 2, world.lanes_count - 1)
                    assert kept in ((0, 1), right)
                    truck_lanes.add("left" if kept == (0, 1) and kept != right else "right")
            moving = world.speed > 0 if "incident" in drawn["traffic"] else slice(None)
            assert np.all(world.speed[moving] == drawn["traffic"]["spawn_speed_mps"])
            again = adapter.reset(seed=seed)
            np.testing.assert_array_equal(world.position, again.position)
    assert lanes == {2, 3, 4, 5, 6} and trucks_changing == {True, False} and truck_lanes == {"left", "right"}


def test_a_random_world_is_seen_through_a_sensor_drawn_from_its_seed():
    from stack.settings.run import episode_sensor

    config = build_config({"scenario": "random", "perception": {"sensor": {"range_m": 150.0}}})
    ranges = config.highway.random_traffic
    assert ranges is not None
    drawn = [episode_sensor(config, seed) for seed in range(30)]
    assert drawn[:3] == [episode_sensor(config, seed) for seed in range(3)], "the seed alone draws it"
    for name in ("position_noise_m", "miss_probability", "false_positives"):
        values = [getattr(sensor, name) for sensor in drawn]
        low, high = getattr(ranges, name)
        assert all(low <= value <= high for value in values) and len(set(values)) == 30, name
    assert {sensor.range_m for sensor in drawn} == {150.0}, "what is not drawn stays the config's"
    fixed = build_config({"perception": {"sensor": {"position_noise_m": 0.3}}}, scenario="dense")
    assert episode_sensor(fixed, 5) is fixed.perception.sensor


def test_random_traffic_spawns_are_feasible_and_every_agent_drives_any_lane_count():
    config = build_config(
        {"episodes": 12, "seed": 31, "planner": {"agent": "rule"}}, scenario="random", highway__duration=3
    )
    assert config.perception.lanes == "absolute", "the rule agent reads the lane count off its state"
    summary = run(config, progress=False).summary
    assert summary["collisions"] == 0 and summary["road_departures"] == 0


@pytest.mark.parametrize(
    "random_traffic, message",
    [
        ({"lanes_count": [5, 3]}, "random_traffic.lanes_count"),
        ({"truck_share": [0.2, 1.5]}, "random_traffic.truck_share"),
        ({"incident_probability": -0.1}, "random_traffic.incident_probability"),
    ],
)
def test_bad_random_traffic_is_refused_in_one_line(random_traffic, message):
    with pytest.raises(ConfigError, match=message) as error:
        build_config({"highway": {"random_traffic": random_traffic}}, "cfg.yaml")
    assert "\n" not in str(error.value)
    with pytest.raises(ConfigError, match="random_traffic: draws the traffic"):
        build_config({"highway": {"random_traffic": {}, "initial_lane_id": 1}}, "cfg.yaml")
