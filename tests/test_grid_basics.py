import numpy as np
import pytest

from perception.grid import GridConfig, OccupancyGridBuilder
from tests.helpers import scene

GRID = GridConfig(cell_length=5.0, cells_ahead=9, cells_behind=2)


def test_one_car_per_lane_at_known_distances():
    world = scene(3, (100.0, 1), [(120.0, 0.0), (110.0, 4.0), (90.0, 8.0)])
    grid = OccupancyGridBuilder(GRID).build(world)
    expected = np.zeros((3, 11), dtype=np.float32)
    # cell k spans [(k - 1/2) 5 m, (k + 1/2) 5 m) around the ego; a 5 m car centred on a cell
    # centre fills exactly that cell: +20 m -> k = 4, +10 m -> k = 2, -10 m -> k = -2.
    expected[0, 2 + 4] = 1
    expected[1, 2 + 2] = 1
    expected[2, 2 - 2] = 1
    np.testing.assert_array_equal(grid.cells, expected)
    assert grid.to_tabular_state().tolist() == [1, 4, 2, 8]


def test_a_car_off_the_cell_centre_marks_both_cells_it_overlaps():
    world = scene(2, (0.0, 0), [(12.0, 0.0)])
    grid = OccupancyGridBuilder(GRID).build(world)
    assert np.flatnonzero(grid.cells[0]).tolist() == [2 + 2, 2 + 3]


def test_paper_state_is_grid_plus_binary_lane_code():
    world = scene(5, (0.0, 3))
    state = OccupancyGridBuilder(GRID).build(world).to_paper_state()
    assert state.shape == (5 * 11 + 3,)
    assert state[-3:].tolist() == [0, 1, 1]


def test_non_finite_vehicle_is_rejected_naming_it():
    world = scene(3, (0.0, 1), [(10.0, 0.0), (float("nan"), 4.0)])
    with pytest.raises(ValueError, match="vehicle id 2 has a non-finite state"):
        OccupancyGridBuilder(GRID).build(world)


@pytest.mark.parametrize("bad", [{"cell_length": 0.0}, {"cell_length": -1.0}, {"cells_ahead": 0}])
def test_grid_config_rejects_empty_grids(bad):
    with pytest.raises(ValueError, match="grid"):
        GridConfig(**bad)
