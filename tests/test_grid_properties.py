"""Perception against highway-env's own OccupancyGrid, property tests, and a curved road."""

import numpy as np
import pytest
from highway_env.envs.common.observation import OccupancyGridObservation
from highway_env.road.lane import CircularLane
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.grid import GridConfig, OccupancyGridBuilder
from records import Actuation, WorldState
from stack.settings.run import build_config
from stack.sim.highway import HighwayAdapter
from tests.helpers import scene

GRID = GridConfig(cell_length=5.0, cells_ahead=9, cells_behind=4)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_centre_mode_agrees_with_highway_env_occupancy_grid(seed):
    """highway-env marks the cell of each vehicle's centre (ego included); set up on our cells:
    x from -(behind + 1/2) L in steps of L, y from the ego's lane edge in steps of a lane width. On
    `jam`, whose ego starts inside the traffic, so the grid holds vehicles."""
    config = GRID.model_copy(update={"footprint": False})
    with HighwayAdapter(build_config({}, scenario="jam").highway) as adapter:
        world = adapter.reset(seed)
        for _ in range(30 * (seed + 1)):
            world = adapter.step(Actuation(0.0, 0.0))
        ego_lane, width, L = int(world.lane[0]), world.lane_width, config.cell_length
        y_low = -world.d[0] + world.lane_offsets[0] - width / 2
        theirs = (
            OccupancyGridObservation(
                adapter.env.unwrapped,
                features=["presence"],
                grid_size=[
                    [-(config.cells_behind + 0.5) * L, (config.cells_ahead - 0.5) * L],
                    [y_low, y_low + world.lanes_count * width],
                ],
                grid_step=[L, width],
            )
            .observe()[0]
            .T
        )
    ours = OccupancyGridBuilder(config).build(world).cells
    assert theirs.shape == ours.shape
    theirs[ego_lane, config.ego_column] = ours[ego_lane, config.ego_column]  # they also mark the ego
    np.testing.assert_array_equal(ours, theirs)
    assert ours.sum() >= 3, "a scene with traffic in the grid"


lanes_counts = st.integers(2, 5)
positions = st.tuples(
    st.integers(-200, 200).map(lambda q: q * 0.25), st.integers(-4, 68).map(lambda q: q * 0.25)
)


@settings(max_examples=60, deadline=None)
@given(lanes=lanes_counts, ego_lane=st.integers(0, 4), others=st.lists(positions, max_size=12))
def test_every_vehicle_in_range_marks_a_cell_and_none_outside_does(lanes, ego_lane, others):
    ego_lane = min(ego_lane, lanes - 1)
    others = [(x, min(y, 4.0 * (lanes - 1) + 1.0)) for x, y in others]
    grid = OccupancyGridBuilder(GRID).build(scene(lanes, (0.0, ego_lane), others))
    low = -(GRID.cells_behind + 0.5) * GRID.cell_length
    high = (GRID.cells_ahead - 0.5) * GRID.cell_length
    for x, y in others:
        alone = OccupancyGridBuilder(GRID).build(scene(lanes, (0.0, ego_lane), [(x, y)]))
        in_range = x + 2.5 > low and x - 2.5 < high
        assert alone.cells.any() == in_range
        if in_range:
            assert (grid.cells >= alone.cells).all()


@settings(max_examples=40, deadline=None)
@given(
    lanes=lanes_counts,
    others=st.lists(positions, max_size=10),
    shift=st.integers(-4000, 4000).map(lambda q: q * 0.5),
)
def test_grid_is_invariant_to_the_egos_absolute_position(lanes, others, shift):
    others = [(x, min(y, 4.0 * (lanes - 1))) for x, y in others]
    here = OccupancyGridBuilder(GRID).build(scene(lanes, (0.0, 0), others))
    moved = OccupancyGridBuilder(GRID).build(scene(lanes, (shift, 0), [(x + shift, y) for x, y in others]))
    np.testing.assert_array_equal(here.cells, moved.cells)


def curved_scene(placements: list[tuple[float, float]], radius: float = 150.0) -> WorldState:
    """Three concentric lanes of a left-hand bend; placements are (arc length on lane 0, lateral)
    and the ego is the first; s and d come from lane 0's local_coordinates, as in the adapter."""
    lanes = tuple(
        CircularLane([0.0, 0.0], radius + 4.0 * k, -np.pi / 2, np.pi / 2, clockwise=False, width=4.0)
        for k in range(3)
    )
    reference = lanes[0]
    position = np.array([reference.position(s, d) for s, d in placements])
    coordinates = np.array([reference.local_coordinates(p) for p in position])
    n = len(placements)
    heading = np.array([reference.heading_at(s) for s, _ in placements])
    return WorldState(
        time=0.0,
        ids=np.arange(n),
        position=position,
        heading=heading,
        speed=np.full(n, 25.0),
        velocity=25.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1),
        lane=np.rint(coordinates[:, 1] / 4.0).astype(int),
        length=np.full(n, 5.0),
        width=np.full(n, 2.0),
        s=coordinates[:, 0],
        d=coordinates[:, 1],
        crashed=np.zeros(n, dtype=bool),
        lanes=lanes,
        lane_offsets=np.array([reference.local_coordinates(lane.position(50.0, 0.0))[1] for lane in lanes]),
    )


def test_curved_road_grid_matches_the_straight_road_grid():
    placements = [(50.0, 4.0), (71.0, 4.0), (61.0, 0.0), (38.0, 8.0), (86.0, 7.0)]
    curved = curved_scene(placements)
    assert curved.lane_offsets.tolist() == pytest.approx([0.0, 4.0, 8.0])
    straight = scene(3, (50.0, 1), placements[1:])
    straight_grid = OccupancyGridBuilder(GRID).build(straight).cells
    curved_grid = OccupancyGridBuilder(GRID).build(curved).cells
    np.testing.assert_array_equal(curved_grid, straight_grid)
    assert np.abs(curved.position[1] - curved.position[0])[1] > 1.0, "the bend is really bending"
