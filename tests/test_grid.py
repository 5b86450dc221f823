"""Perception: hand-placed scenes with exact grids, encodings, modes, features, bad input."""

import dataclasses

import numpy as np
import pytest
from pydantic import ValidationError

from perception.grid import GridConfig, OccupancyGridBuilder
from records import lane_code_bits
from tests.helpers import scene

GRID = GridConfig(cell_length=5.0, cells_ahead=9, cells_behind=2)
EGO_COLUMN = 2


def build(world, config=GRID):
    return OccupancyGridBuilder(config).build(world)


def expected_grid(lanes: int, marks: list[tuple[int, int]], rows: int | None = None) -> np.ndarray:
    """Marks are (row, cells ahead of the ego)."""
    grid = np.zeros((rows or lanes, GRID.cells), dtype=np.float32)
    for row, ahead in marks:
        grid[row, EGO_COLUMN + ahead] = 1
    return grid


def test_one_car_per_lane_at_known_distances():
    world = scene(3, (100.0, 1), [(120.0, 0.0), (110.0, 4.0), (90.0, 8.0)])
    grid = build(world)
    # cell k spans [(k - 1/2) 5 m, (k + 1/2) 5 m) around the ego; a 5 m car centred on a cell
    # centre fills exactly that cell: +20 m -> k = 4, +10 m -> k = 2, -10 m -> k = -2.
    np.testing.assert_array_equal(grid.cells, expected_grid(3, [(0, 4), (1, 2), (2, -2)]))
    assert grid.to_tabular_state().tolist() == [1, 4, 2, 8]


def test_a_car_off_the_cell_centre_marks_both_cells_it_overlaps():
    grid = build(scene(2, (0.0, 0), [(12.0, 0.0)]))
    np.testing.assert_array_equal(grid.cells, expected_grid(2, [(0, 2), (0, 3)]))


def test_a_car_exactly_on_a_cell_border_marks_only_the_cells_it_enters():
    # cells are half-open: [12.5, 17.5) is cell 3, [17.5, 22.5) cell 4
    grid = build(scene(2, (0.0, 0), [(15.0, 0.0)]))  # footprint [12.5, 17.5]: touches cell 4's border
    np.testing.assert_array_equal(grid.cells, expected_grid(2, [(0, 3)]))
    grid = build(scene(2, (0.0, 0), [(20.0, 0.0)]))  # [17.5, 22.5]: rear bumper on the border
    np.testing.assert_array_equal(grid.cells, expected_grid(2, [(0, 4)]))
    grid = build(scene(2, (0.0, 0), [(17.5, 0.0)]))  # [15, 20]: centre on the border, both cells
    np.testing.assert_array_equal(grid.cells, expected_grid(2, [(0, 3), (0, 4)]))


def test_a_car_straddling_two_lanes_marks_both():
    grid = build(scene(3, (0.0, 0), [(20.0, 6.0)]))  # between lane 1 (d=4) and lane 2 (d=8)
    np.testing.assert_array_equal(grid.cells, expected_grid(3, [(1, 4), (2, 4)]))
    grid = build(scene(3, (0.0, 0), [(20.0, 4.9)]))  # footprint [3.9, 5.9]: lane 1 and just lane 1
    np.testing.assert_array_equal(grid.cells, expected_grid(3, [(1, 4)]))


def test_empty_road():
    grid = build(scene(4, (0.0, 2)))
    assert not grid.cells.any()
    assert grid.to_tabular_state().tolist() == [2, 8, 8, 8, 8]


@pytest.mark.parametrize("lanes", [2, 3, 4, 5])
@pytest.mark.parametrize("ego_at", ["left", "right"])
def test_ego_in_the_outer_lanes_for_every_lane_count(lanes, ego_at):
    ego_lane = 0 if ego_at == "left" else lanes - 1
    others = [(10.0 + 5.0 * k, 4.0 * k) for k in range(lanes)]
    grid = build(scene(lanes, (0.0, ego_lane), others))
    np.testing.assert_array_equal(grid.cells, expected_grid(lanes, [(k, 2 + k) for k in range(lanes)]))
    assert grid.ego_lane == ego_lane
    assert grid.to_paper_state().shape == (lanes * GRID.cells + max(1, int(np.ceil(np.log2(lanes)))),)
    bits = lane_code_bits(lanes)
    ego_lane_bits = [(ego_lane >> (bits - 1 - bit)) & 1 for bit in range(bits)]
    np.testing.assert_array_equal(grid.to_paper_state()[-bits:], ego_lane_bits)


def test_ego_relative_rows_mark_missing_lanes_occupied():
    config = GRID.model_copy(update={"lanes": "ego", "lateral_reach": 1})
    world = scene(3, (0.0, 0), [(10.0, 0.0), (20.0, 4.0), (30.0, 8.0)])
    grid = build(world, config)
    expected = expected_grid(3, [(1, 2), (2, 4)], rows=3)
    expected[0] = 1  # left of lane 0 is off the road
    np.testing.assert_array_equal(grid.cells, expected)
    assert grid.ego_row == 1
    right = build(scene(3, (0.0, 2), [(10.0, 8.0), (20.0, 4.0)]), config)
    assert (
        right.cells[2].all() and right.cells[1, EGO_COLUMN + 2] == 1 and right.cells[0, EGO_COLUMN + 4] == 1
    )


def test_the_same_ego_relative_grid_on_any_lane_count():
    config = GRID.model_copy(update={"lanes": "ego", "lateral_reach": 1})
    small = build(scene(3, (0.0, 1), [(10.0, 0.0), (20.0, 8.0)]), config)
    large = build(scene(5, (0.0, 3), [(10.0, 8.0), (20.0, 16.0)]), config)
    np.testing.assert_array_equal(small.cells, large.cells)


@pytest.mark.parametrize("encoding", ["observation", "paper"])
def test_side_lanes_code_makes_the_encodings_independent_of_the_lane_count(encoding):
    config = GRID.model_copy(
        update={"lanes": "ego", "lane_code": "sides", "features": ("relative_speed", "ttc", "ego_speed")}
    )
    builder = OccupancyGridBuilder(config)
    sizes = {builder.space(encoding, lanes).shape[0] for lanes in (2, 3, 4, 5, 6, 8)}
    assert len(sizes) == 1
    for lanes, ego_lane, sides in [
        (3, 1, [0.5, 0.5]),
        (5, 0, [0.0, 1.0]),
        (6, 4, [1.0, 0.5]),
        (2, 1, [0.5, 0]),
    ]:
        grid = builder.build(scene(lanes, (0.0, ego_lane), [(20.0, 4.0 * ego_lane)]))
        encoded = grid.encode(encoding)
        assert encoded.shape[0] in sizes and builder.space(encoding, lanes).contains(encoded)
        np.testing.assert_array_equal(encoded[-2:], sides), "lanes left, lanes right, capped at 2, over 2"


def test_the_tabular_state_with_the_side_lanes_code_fits_one_table_on_any_road():
    builder = OccupancyGridBuilder(
        GRID.model_copy(update={"lanes": "ego", "lane_code": "sides", "lateral_reach": 1})
    )
    assert {builder.tabular_space(lanes).high.tolist()[0] for lanes in (2, 3, 4, 5, 6)} == {3}
    for lanes, ego_lane, where in [(5, 0, 1), (5, 2, 3), (5, 4, 2), (3, 1, 3), (6, 5, 2)]:
        state = builder.build(scene(lanes, (0.0, ego_lane), [(20.0, 4.0 * ego_lane)])).to_tabular_state()
        assert state[0] == where, "2 x (a lane on the left) + (a lane on the right)"
        assert state[1 + 1] == 4 and builder.tabular_space(lanes).contains(state), "the car 20 m ahead"


def test_ego_lateral_feature_shows_a_lane_change_under_way():
    config = GRID.model_copy(update={"features": ("ego_lateral",)})
    builder = OccupancyGridBuilder(config)
    world = scene(3, (0.0, 1), [(30.0, 0.0)])
    assert build(world, config).ego_lateral.tolist() == [0.0, 0.0]
    changing = dataclasses.replace(world, d=world.d + np.array([1.0, 0.0]), heading=np.array([0.05, 0.0]))
    grid = build(changing, config)
    np.testing.assert_allclose(grid.ego_lateral, [0.25, 0.25])
    assert builder.observation_space(3).contains(grid.to_observation())
    assert grid.to_observation().shape == builder.observation_space(3).shape


def test_side_lanes_code_needs_ego_relative_rows():
    with pytest.raises(ValidationError, match="lane_code: sides needs lanes: ego"):
        GridConfig(lane_code="sides")


def test_tabular_state_caps_at_the_line_of_sight():
    grid = build(scene(2, (0.0, 0), [(40.0, 0.0), (20.0, 4.0)]))
    assert grid.to_tabular_state().tolist() == [0, 8, 4]
    assert grid.to_tabular_state(line_of_sight=5).tolist() == [0, 4, 4]
    assert grid.to_tabular_state(line_of_sight=3).tolist() == [0, 2, 2]


def test_spaces_contain_their_encodings():
    config = GRID.model_copy(update={"features": ("relative_speed", "ttc")})
    builder = OccupancyGridBuilder(config)
    grid = builder.build(scene(4, (0.0, 1), [(20.0, 4.0), (-10.0, 8.0)], other_speed=35.0))
    assert builder.paper_space(4).contains(grid.to_paper_state())
    assert builder.observation_space(4).contains(grid.to_observation())
    assert builder.tabular_space(4).contains(grid.to_tabular_state())


def test_relative_speed_and_time_to_collision_features():
    config = GRID.model_copy(
        update={"features": ("relative_speed", "ttc"), "speed_scale": 20.0, "ttc_horizon": 10.0}
    )
    world = scene(2, (0.0, 0), [(25.0, 0.0), (30.0, 4.0)], speed=25.0, other_speed=20.0)
    grid = build(world, config)
    assert grid.relative_speed[0, EGO_COLUMN + 5] == pytest.approx(-0.25)
    assert grid.relative_speed[1, EGO_COLUMN + 6] == pytest.approx(-0.25)
    assert grid.relative_speed[0, EGO_COLUMN] == 0.0
    # gap 25 - 5 = 20 m closing at 5 m/s: 4 s -> 0.4; lane 1: 25 m / 5 m/s = 5 s -> 0.5
    np.testing.assert_allclose(grid.ttc, [0.4, 0.5])
    opening = build(scene(2, (0.0, 0), [(25.0, 0.0)], speed=20.0, other_speed=25.0), config)
    np.testing.assert_allclose(opening.ttc, [1.0, 1.0])


def test_traffic_feature_describes_each_lanes_traffic_far_beyond_the_grid():
    """Per row within TRAFFIC_RANGE ahead: mean and lowest relative speed, the share of the range
    the vehicles' lengths fill; a stopped car 150 m ahead (past the grid's 45 m) shows at -1."""
    config = GRID.model_copy(
        update={"lanes": "ego", "lateral_reach": 1, "features": ("traffic",), "speed_scale": 20.0}
    )
    stopped = dataclasses.replace(
        scene(3, (0.0, 0), [(150.0, 0.0), (100.0, 4.0), (60.0, 4.0), (250.0, 4.0), (-30.0, 4.0)], speed=25.0),
    )
    stopped.speed[1] = 0.0
    grid = build(stopped, config)
    assert grid.cells[1].sum() == 0, "nothing in the ego's lane within the grid"
    # row 0 is off the road; row 1 the ego's lane: the stopped car, -25 / 20 clipped to -1, 5 of 200 m
    # row 2 (lane 1): the cars at +60 and +100 m (20 m/s: -0.25), not those at +250 and -30 m
    np.testing.assert_allclose(grid.traffic, [[0, 0, 1], [-1, -1, 0.025], [-0.25, -0.25, 0.05]])
    empty = build(scene(3, (0.0, 1)), config)
    np.testing.assert_allclose(empty.traffic, np.zeros((3, 3)))
    builder = OccupancyGridBuilder(config)
    assert builder.observation_space(3).contains(grid.to_observation())
    np.testing.assert_array_equal(grid.to_observation()[-2 - 9 : -2], grid.traffic.ravel())


def test_observation_layout_gives_every_part_in_feature_order():
    config = GRID.model_copy(
        update={"lanes": "ego", "lane_code": "sides", "features": ("traffic", "ego_speed", "ttc")}
    )
    layout = config.observation_layout(4)
    assert layout == [("presence", 33), ("ttc", 3), ("ego_speed", 1), ("traffic", 9), ("lane", 2)]
    space = OccupancyGridBuilder(config).observation_space(4)
    assert space.shape == (48,) and space.low[-11:-2].tolist() == [-1, -1, 0] * 3


def test_non_finite_vehicle_is_rejected_naming_it():
    world = scene(3, (0.0, 1), [(10.0, 0.0), (float("nan"), 4.0)])
    with pytest.raises(ValueError, match="vehicle id 2 has a non-finite state"):
        build(world)
    world = scene(3, (0.0, 1), [(10.0, 0.0), (np.inf, 4.0)])
    with pytest.raises(ValueError, match="vehicle id 2"):
        build(world)


@pytest.mark.parametrize(
    "bad",
    [
        {"cell_length": 0.0},
        {"cell_length": -1.0},
        {"cell_length": float("nan")},
        {"cells_ahead": 0},
        {"lanes": "sideways"},
        {"features": ("colour",)},
    ],
)
def test_grid_config_rejects_bad_grids(bad):
    with pytest.raises(ValidationError):
        GridConfig(**bad)
