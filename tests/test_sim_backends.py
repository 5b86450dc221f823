"""The fast and vector backends must reproduce stock highway-env exactly: every vehicle, every frame,
bit for bit (positions, headings, speeds, lane and target lane indices, crash flags)."""

import functools
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle

from stack.settings.run import ConfigError, HighwayConfig, build_config
from stack.sim import envs
from stack.sim.envs import FAST_HIGHWAY, VECTOR_HIGHWAY
from stack.sim.highway import HighwayAdapter, env_config
from stack.sim.traffic import TrafficVehicle
from stack.sim.vector.lanes import LaneTable
from stack.sim.vector.motion import Footprints, close_pairs
from stack.sim.vector.road import VectorRoad

BACKENDS = {"fast": FAST_HIGHWAY, "vector": VECTOR_HIGHWAY}


def ramming(frame: int) -> np.ndarray:
    """An ego at full throttle with a slight weave: it rear-ends traffic; frames go on after the
    crash, so the crash physics (impact, braking to a stop) is compared too."""
    return np.array([1.0, 0.02 * np.sin(frame / 15.0)])


def braking(frame: int) -> np.ndarray:
    """An ego that keeps braking: the traffic slows down behind it, and queues up to a standstill
    behind a stopped car."""
    return np.array([-0.3, 0.0])


DRIVERS = {"ramming": ramming, "braking": braking}


def state(vehicle) -> list[float]:
    target = getattr(vehicle, "target_lane_index", vehicle.lane_index)
    return [
        *vehicle.position,
        vehicle.heading,
        vehicle.speed,
        vehicle.lane_index[2],
        target[2],
        vehicle.crashed,
        type(vehicle) is TrafficVehicle,
    ]


def trajectory(
    env_id: str, highway: HighwayConfig, seed: int, frames: int, driver: str = "ramming"
) -> list[np.ndarray]:
    return _trajectory(env_id, highway.model_dump_json(), seed, frames, driver)


@functools.cache
def _trajectory(env_id: str, highway_json: str, seed: int, frames: int, driver: str) -> list[np.ndarray]:
    highway = HighwayConfig.model_validate_json(highway_json)
    env = gym.make(env_id, config=env_config(highway), disable_env_checker=True)
    env.reset(seed=seed)
    states = []
    for frame in range(frames):
        _, _, _, truncated, _ = env.step(DRIVERS[driver](frame))
        states.append(np.array([state(v) for v in env.unwrapped.road.vehicles]))
        if truncated:
            break
    env.close()
    return states


def assert_identical(
    highway: HighwayConfig, seed: int, frames: int, backend: str = "fast", driver: str = "ramming"
) -> list[np.ndarray]:
    stock = trajectory("drivestack/Highway-v0", highway, seed, frames, driver)
    other = trajectory(BACKENDS[backend], highway, seed, frames, driver)
    assert len(other) == len(stock)
    for frame, (a, b) in enumerate(zip(stock, other, strict=True)):
        np.testing.assert_array_equal(
            b.view(np.uint64), a.view(np.uint64), err_msg=f"{backend}, frame {frame}"
        )
    return stock


def traffic_lane_changes(states: list[np.ndarray]) -> int:
    lanes = np.array([s[1:, 4] for s in states])
    return int(np.count_nonzero(np.diff(lanes, axis=0)))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    ("seed", "density", "vehicles", "frames"),
    [
        # seed 0, slow: seed 1 here and seed 9 (the crash and lane-change run below) drive the same road
        pytest.param(0, 1.0, 50, 200, marks=pytest.mark.slow),
        (1, 1.0, 50, 200),
        # dense traffic, slow: the `dense` scenario below drives dense traffic in the default suite
        pytest.param(2, 2.0, 100, 120, marks=pytest.mark.slow),
    ],
)
def test_backend_matches_stock(backend, seed, density, vehicles, frames):
    highway = HighwayConfig(vehicles_count=vehicles, vehicles_density=density)
    assert_identical(highway, seed, frames, backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_short_runs_cover_crashes_and_traffic_lane_changes(backend):
    """Seed 9: the ramming ego reaches a car within 200 frames of a drivable start."""
    states = assert_identical(HighwayConfig(vehicles_count=50), seed=9, frames=200, backend=backend)
    assert states[-1][:, 6].sum() >= 2, "the ramming ego must crash into someone"
    assert traffic_lane_changes(states) > 0


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    "lanes", [2, pytest.param(3, marks=pytest.mark.slow), pytest.param(5, marks=pytest.mark.slow), 6]
)
def test_backend_matches_stock_on_other_lane_counts(backend, lanes):
    """The fewest and the most lanes (3 and 5, slow, lie between; 4 is every other test's road)."""
    highway = HighwayConfig(lanes_count=lanes, vehicles_count=30)
    assert_identical(highway, seed=lanes, frames=150, backend=backend)


@pytest.mark.parametrize("scenario", ["overtaking", "dense", "lanes-5"])
def test_vector_backend_matches_stock_on_the_scenarios(scenario):
    """Heterogeneous classes (per-vehicle lengths, desired speeds), the ego inside the traffic,
    dense traffic and 5 lanes."""
    states = assert_identical(
        build_config({}, scenario=scenario).highway, seed=11, frames=150, backend="vector"
    )
    assert traffic_lane_changes(states) > 0


@pytest.mark.parametrize(
    "backend", [pytest.param(b, marks=pytest.mark.slow) if b == "fast" else b for b in BACKENDS]
)
def test_traffic_queues_to_a_standstill_without_reversing_alike_on_every_backend(backend):
    """Behind a stopped car (which stays exactly where it is) and a braking ego, the `incident`
    traffic queues up to speed 0 and stays there (stock highway-env's vehicles reverse there, down
    to -40 m/s), on every backend alike."""
    states = assert_identical(
        build_config({}, scenario="incident").highway, seed=0, frames=300, backend=backend, driver="braking"
    )
    speeds = np.concatenate([s[s[:, -1] == 1, 3] for s in states])
    assert speeds.min() >= -1e-12, "no more than float rounding below 0"
    assert np.count_nonzero(speeds == 0.0) > 100
    first = states[0]
    (stopped,) = np.flatnonzero((first[:, -1] == 0) & (first[:, 3] == 0.0))
    assert {tuple(s[stopped, :2]) for s in states} == {tuple(first[stopped, :2])}, "the incident stays put"


@pytest.mark.slow
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("seed", "density"), [(0, 1.0), (1, 1.5), (2, 2.0)])
def test_backend_matches_stock_over_full_episodes(backend, seed, density):
    states = assert_identical(HighwayConfig(vehicles_density=density), seed, frames=600, backend=backend)
    assert len(states) == 600, "every frame of the 40 s episode was compared"


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 4])
def test_vector_backend_matches_stock_over_full_overtaking_episodes(seed):
    highway = build_config({}, scenario="overtaking").highway
    assert len(assert_identical(highway, seed, frames=600, backend="vector")) == 600


def test_array_operations_give_the_bits_of_the_scalar_ones():
    """Why the vector backend can be exact: on this machine's numpy, every ufunc it uses gives the
    same bits on an array as on each element alone (SIMD and scalar paths agree), and `np.vecdot`
    rounds a 2-vector dot product as `np.dot` does (plain `a0*b0 + a1*b1` does not)."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-1.0, 1.0, 20_000)
    for ufunc in (np.arcsin, np.arctan, np.tan, np.cos, np.sin, np.sqrt, np.abs):
        values = np.abs(x) if ufunc is np.sqrt else x
        assert np.array_equal(ufunc(values), [ufunc(float(v)) for v in values]), ufunc.__name__
    base, exponent = rng.uniform(0, 3, 20_000), rng.uniform(3.5, 4.5, 20_000)
    assert np.array_equal(
        np.power(base, exponent), [np.power(float(b), e) for b, e in zip(base, exponent, strict=True)]
    )
    assert np.array_equal(np.power(base, 2), [np.power(float(b), 2) for b in base])
    angle = rng.uniform(-10, 10, 20_000)
    wrapped = [((float(a) + np.pi) % (2 * np.pi)) - np.pi for a in angle]
    assert np.array_equal(((angle + np.pi) % (2 * np.pi)) - np.pi, wrapped)
    a, b = rng.normal(size=(20_000, 2)) * 30, rng.normal(size=(20_000, 2))
    assert np.array_equal(np.vecdot(a, b), [np.dot(u, v) for u, v in zip(a, b, strict=True)])


def test_roads_with_curved_lanes_run_as_the_fast_road():
    env = gym.make("exit-v0", disable_env_checker=True)
    env.reset(seed=0)
    assert LaneTable.fit(env.unwrapped.road.network) is None
    highway = gym.make(VECTOR_HIGHWAY, config=env_config(HighwayConfig()), disable_env_checker=True)
    highway.reset(seed=0)
    assert isinstance(highway.unwrapped.road, VectorRoad)
    assert LaneTable.fit(highway.unwrapped.road.network) is not None


def test_vector_is_the_default_backend():
    assert build_config({}).sim.backend == "vector"


def test_unknown_backend_is_refused_with_the_list():
    with pytest.raises(
        ConfigError, match="sim.backend: unknown backend 'turbo'; available: vector, fast, stock"
    ):
        build_config({"sim": {"backend": "turbo"}})
    with pytest.raises(ValueError, match="available: vector, fast, stock"):
        HighwayAdapter(HighwayConfig(), backend="turbo")


@pytest.mark.parametrize(("lanes", "vehicles"), [(6, 3), (1, 10)])
def test_vector_backend_matches_stock_on_sparse_roads(lanes, vehicles):
    """Lanes nobody drives on (empty neighbour queries) and a road without side lanes."""
    assert_identical(
        HighwayConfig(lanes_count=lanes, vehicles_count=vehicles), seed=5, frames=120, backend="vector"
    )


@pytest.mark.parametrize("order", ["stack, gymnasium", "gymnasium, stack"])
def test_importing_stack_registers_its_envs_whether_gymnasium_comes_first_or_later(order):
    """`import stack` registers the envs without importing gymnasium (the CLI starts light): at once
    when gymnasium is there, else as gymnasium is imported."""
    probe = (
        f"import sys, {order}\n"
        "print(sorted(name for name in gymnasium.registry if name.startswith('drivestack/')))"
    )
    completed = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    ids = [
        envs.HIGHWAY,
        envs.FAST_HIGHWAY,
        envs.VECTOR_HIGHWAY,
        envs.FAST_HIGHWAY_FAST,
        envs.EXIT,
        envs.FAST_EXIT,
    ]
    assert completed.stdout.strip() == str(sorted([*ids, envs.HIERARCHICAL_HIGHWAY, envs.DEEPCARS]))
    alone = subprocess.run(
        [sys.executable, "-c", "import sys, stack; print('gymnasium' in sys.modules)"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert alone.stdout.strip() == "False"


def test_close_pairs_keep_every_pair_highway_env_finds_touching_or_about_to():
    """The compiled candidate filter against highway-env's own test, pair by pair, on crowded
    random scenes (vehicles of mixed sizes, headings and speeds packed into 60 m x 12 m): every pair
    whose rectangles intersect now or over the frame is kept, and it drops most that do not."""
    road = Road(RoadNetwork.straight_road_network(3), np_random=np.random.default_rng(0))
    rng = np.random.default_rng(7)
    kept = missed = touching = 0
    for _ in range(40):
        vehicles = []
        for _ in range(30):
            vehicle = Vehicle(
                road, rng.uniform([0, -2], [60, 10]), rng.uniform(-0.6, 0.6), rng.uniform(0, 35)
            )
            vehicle.LENGTH, vehicle.WIDTH = rng.uniform(3, 12), rng.uniform(1.6, 2.6)
            vehicle.diagonal = float(np.hypot(vehicle.LENGTH, vehicle.WIDTH))
            vehicles.append(vehicle)
        pairs = {tuple(pair) for pair in close_pairs(Footprints.of(vehicles), 1 / 15).tolist()}
        kept += len(pairs)
        for i in range(len(vehicles)):
            for j in range(i + 1, len(vehicles)):
                intersecting, will_intersect, _ = vehicles[i]._is_colliding(vehicles[j], 1 / 15)
                if intersecting or will_intersect:
                    touching += 1
                    missed += (i, j) not in pairs
    assert touching > 100
    assert missed == 0
    assert kept < 2 * touching


def test_the_closest_lane_kernel_picks_numpys_lane_on_every_input():
    """`LaneTable.closest` (compiled) against highway-env's `distance_with_heading` minimum as numpy
    computes it: on the lane boundaries, at headings of +-pi and beyond, off both road ends, with
    NaN and infinite inputs (numpy's argmin: the first minimum, the first NaN)."""
    table = LaneTable(RoadNetwork.straight_road_network(4, length=1000))
    rng = np.random.default_rng(3)

    def numpy_closest(position: np.ndarray, heading: np.ndarray) -> np.ndarray:
        s = (position[:, 0] - table.start[0, 0]) * table.direction[0] + (
            position[:, 1] - table.start[0, 1]
        ) * table.direction[1]
        delta = position[None, :, :] - table.start[:, None, :]
        r = delta[..., 0] * table.lateral[:, 0, None] + delta[..., 1] * table.lateral[:, 1, None]
        angle = np.abs(((heading[None, :] - table.heading[:, None] + np.pi) % (2 * np.pi)) - np.pi)
        distance = np.abs(r) + np.maximum(s - table.length[:, None], 0) + np.maximum(0 - s, 0) + angle
        return np.argmin(distance, axis=0)

    for case in range(300):
        count = int(rng.integers(1, 40))
        lateral = [rng.uniform(-6, 18, count), np.round(rng.uniform(-6, 18, count) * 2) / 2][case % 2]
        position = np.stack([rng.uniform(-50, 1050, count), lateral], axis=1)
        heading = [rng.uniform(-10, 10, count), np.full(count, np.pi), np.full(count, -np.pi)][case % 3]
        if case % 10 == 0:
            position[0, int(rng.integers(2))] = np.nan
            heading[-1] = np.inf
        with np.errstate(invalid="ignore"):
            expected = numpy_closest(position, heading)
        x, y = position.T.copy()
        np.testing.assert_array_equal(table.closest(x, y, heading), expected, err_msg=f"case {case}")


def vector_env_after(scenario: str, seed: int, frames: int) -> gym.Env:
    """A vector-backend env of `scenario` reset with `seed` and driven `frames` frames (braking)."""
    highway = build_config({}, scenario=scenario).highway
    env = gym.make(VECTOR_HIGHWAY, config=env_config(highway), disable_env_checker=True)
    env.reset(seed=seed)
    for frame in range(frames):
        env.step(braking(frame))
    return env


def test_a_frames_idm_is_highway_envs_bit_for_bit():
    """`TrafficFrame.idm` (compiled arithmetic around numpy's powers and dot products) against
    `IDMVehicle.acceleration` for every vehicle behind every other, and without a leader or an ego,
    on dense traffic after some frames (lane changes under way, speed limits on)."""
    from highway_env.vehicle.behavior import IDMVehicle

    from stack.sim.fast_road import LaneProjections
    from stack.sim.vector.road import DRIVER_CONSTANTS
    from stack.sim.vector.road_frame import DriverLaws, TrafficFrame

    env = vector_env_after("dense", seed=5, frames=40)
    road = env.unwrapped.road
    frame = TrafficFrame(LaneProjections(road), LaneTable.fit(road.network))
    objects = frame.projections.objects
    judge = next(v for v in objects if isinstance(v, IDMVehicle))
    rows = np.arange(-1, len(objects))
    ego, front = (grid.ravel() for grid in np.meshgrid(rows, rows, indexing="ij"))
    constants = np.array(DRIVER_CONSTANTS(judge)[1:], dtype=float)
    laws = DriverLaws.of(*(np.array([value]) for value in constants))
    expected = [
        judge.acceleration(objects[e] if e >= 0 else None, objects[f] if f >= 0 else None)
        for e, f in zip(ego.tolist(), front.tolist(), strict=True)
    ]
    got = frame.idm(ego, front, laws, np.zeros(len(ego), dtype=int))
    np.testing.assert_array_equal(got.view(np.uint64), np.array(expected, dtype=float).view(np.uint64))
    env.close()


def test_the_step_reads_what_the_act_left_and_the_kept_constants_follow_the_vehicles():
    """After `act`, the vector step takes the movers' state and the drivers' actions from the act's
    arrays, and the next act the vehicles' state from where the step left them (the same numbers the
    vehicles hold); the vehicles' constants are kept only while the same vehicles drive: a vehicle
    replaced is read afresh."""
    from stack.sim.vector.motion import MOVER_CONSTANTS, KeptColumns, columns

    env = vector_env_after("overtaking", seed=3, frames=5)
    road = env.unwrapped.road
    road.act()
    acted = road.acted_for_step
    assert acted is not None and len(acted.vehicles) == len(road.vehicles)
    np.testing.assert_array_equal(acted.speed, [v.speed for v in road.vehicles])
    np.testing.assert_array_equal(acted.position, [v.position for v in road.vehicles])
    driven = [road.vehicles[row] for row in acted.driven.tolist()]
    np.testing.assert_array_equal(acted.steering, [v.action["steering"] for v in driven])
    road.step(1 / 15)
    assert road.acted_for_step is None and road.mover_constants is not None
    left = road.left_by_step
    assert left is not None
    np.testing.assert_array_equal(left.footprints.heading, [v.heading for v in road.vehicles])
    lane_row = LaneTable.fit(road.network).row
    np.testing.assert_array_equal(left.lane_row, [lane_row[v.lane_index] for v in road.vehicles])
    road.act()
    assert road.left_by_step is None and road.acted_for_step is not None
    np.testing.assert_array_equal(road.acted_for_step.position, [v.position for v in road.vehicles])
    kept = road.mover_constants
    assert KeptColumns.of(list(road.vehicles), MOVER_CONSTANTS, kept) is kept
    replaced = list(road.vehicles)
    replaced[-1] = road.vehicles[0].create_from(road.vehicles[0])
    replaced[-1].LENGTH = 12.0
    fresh = KeptColumns.of(replaced, MOVER_CONSTANTS, kept)
    assert fresh is not kept
    np.testing.assert_array_equal(fresh.rows, columns(replaced, MOVER_CONSTANTS))
    assert fresh.rows[2, -1] == 12.0
    env.close()


DROP_IN_CONFIGS = {
    "6 lanes": {"lanes_count": 6},
    "80 vehicles at density 2.5": {"vehicles_count": 80, "vehicles_density": 2.5},
    "aggressive drivers": {"other_vehicles_type": "highway_env.vehicle.behavior.AggressiveVehicle"},
    "2 lanes": {"lanes_count": 2},
}


@pytest.mark.parametrize("config", DROP_IN_CONFIGS.values(), ids=DROP_IN_CONFIGS.keys())
@pytest.mark.parametrize(
    "env_id",
    [
        pytest.param("drivestack/Highway-v0", marks=pytest.mark.slow),
        pytest.param("drivestack/FastHighway-v0", marks=pytest.mark.slow),
        "drivestack/VectorHighway-v0",
    ],
)
def test_the_drop_in_ids_are_highway_v0_vehicle_for_vehicle(env_id, config):
    """Issue 49 (4): made with highway-v0's config, the stack's gym ids give highway-v0's traffic
    (they diverged at the first frame by 22-551 m: the stack's feasible spawns applied to them)."""
    stock, ours = gym.make("highway-v0", config=config), gym.make(env_id, config=config)

    def vehicles(env: gym.Env) -> np.ndarray:
        return np.array([[*v.position, v.speed, v.heading] for v in env.unwrapped.road.vehicles])

    stock.reset(seed=7), ours.reset(seed=7)
    for _ in range(4):
        np.testing.assert_array_equal(vehicles(ours), vehicles(stock))
        stock.step(1), ours.step(1)


@pytest.mark.parametrize("driver", DRIVERS)
def test_the_exit_road_on_the_fast_road_matches_stock(driver):
    """The exit's curve searched through its own distance, its straight lanes in plain floats: every
    vehicle's state and full lane index (segment included), frame for frame, as stock's."""
    highway = build_config({}, scenario="exit").highway
    runs = []
    for env_id in (envs.EXIT, envs.FAST_EXIT):
        env = gym.make(env_id, config=env_config(highway), disable_env_checker=True)
        env.reset(seed=3)
        frames = []
        for frame in range(150):
            _, _, _, truncated, _ = env.step(DRIVERS[driver](frame))
            vehicles = env.unwrapped.road.vehicles
            frames.append(([state(v) for v in vehicles], [v.lane_index for v in vehicles]))
            if truncated:
                break
        env.close()
        runs.append(frames)
    assert len(runs[0]) == len(runs[1]) > 100
    for frame, (stock, fast) in enumerate(zip(*runs, strict=True)):
        np.testing.assert_array_equal(np.array(fast[0]).view(np.uint64), np.array(stock[0]).view(np.uint64))
        assert fast[1] == stock[1], frame
    assert any(index[1] == "exit" for index in runs[0][-1][1]) or any(
        index[0] == "1" for index in runs[0][-1][1]
    ), "vehicles reach the exit's segments"
