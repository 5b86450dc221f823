"""A decision agent plug-in in a plain file: no package, no registration (docs/plugins.md).

    drivestack compare --agents examples/plugin_agent.py:LeftWhenBlocked,keep-lane --episodes 5
    .venv/bin/python examples/plugin_agent.py     # one episode through the Python API

The `Agent` protocol: `encoding` (what the loop shows it), `grid_config` (None: the run's grid) and
SB3's `predict(observation, state, episode_start, deterministic) -> (action, state)`, the action an
index of LEFT, STAY, RIGHT. The constructor may ask for `lanes`, `grid`, `seed` and `model`.
"""

from pathlib import Path

import numpy as np


class LeftWhenBlocked:
    """Asks for the left lane whenever a car is in sight ahead in its own lane (the safety layer
    refuses the unsafe requests)."""

    encoding = "paper"
    grid_config = None

    def __init__(self, lanes: int, grid) -> None:
        self.grid = grid
        self.size = grid.rows(lanes) * grid.cells
        self.ego_row = grid.lateral_reach if grid.lanes == "ego" else None

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        cells = np.asarray(observation).reshape(-1)[: self.size].reshape(-1, self.grid.cells)
        row = cells.shape[0] // 2 if self.ego_row is None else self.ego_row
        blocked = cells[row, self.grid.ego_column + 1 :].any()
        return np.array(0 if blocked else 1), state


if __name__ == "__main__":
    import stack

    config = stack.build_config(
        {"planner": {"agent": f"{Path(__file__).resolve()}:LeftWhenBlocked"}, "highway": {"duration": 10}}
    )
    result = stack.run_episode(config, episode=0)
    print(f"one 10-s episode: mean speed {result.mean_speed:.1f} m/s, {result.lane_changes} lane changes")
