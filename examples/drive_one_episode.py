"""drivestack from Python: a grid from your own highway-env env, an agent's decision on it, and one
closed-loop episode of the full stack.

    .venv/bin/python examples/drive_one_episode.py
"""

import gymnasium as gym
import highway_env  # noqa: F401  (registers highway-v0)

import stack
from perception import GridConfig, OccupancyGridBuilder
from planner import decide, make_agent

# 1. Any highway-env env you made: its state as a WorldState, then the occupancy grid around the ego.
env = gym.make("highway-v0", config={"lanes_count": 3, "vehicles_count": 15})
env.reset(seed=0)
world = stack.world_state(env)
grid_config = GridConfig(lanes="ego", lane_code="sides", features=("relative_speed", "ttc"))
grid = OccupancyGridBuilder(grid_config).build(world)
print(f"ego in lane {grid.ego_lane} of {world.lanes_count}; presence grid (rows = lanes around the ego):")
print(grid.cells.astype(int))

# 2. A decision agent on that grid: MOBIL here; `make_agent("ddqn", ...)` loads the shipped model.
agent = make_agent("mobil", world.lanes_count, grid_config)
print("MOBIL says:", decide(agent, grid.encode(agent.encoding)).name)

# 3. The whole stack closed-loop (perception -> agent -> safety -> maneuver -> PID): one episode.
config = stack.build_config(
    {"planner": {"agent": "mobil"}, "highway": {"duration": 10}}, scenario="overtaking"
)
result = stack.run_episode(config, episode=0)
print(
    f"one 10-s episode of `overtaking`: mean speed {result.mean_speed:.1f} m/s, "
    f"{result.lane_changes} lane changes, crashed: {result.crashed}"
)
env.close()
