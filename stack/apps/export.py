"""`drivestack export MODEL --sb3 OUT.zip`: a drivestack model file as a stable-baselines3 zip.

The Q-network's weights go into SB3's own `DQN` (its `MlpPolicy` with the same hidden layers), with
the observation space of the model's encoding and `Discrete(3)` actions, so `DQN.load(OUT)` opens it
for evaluation or fine-tuning with SB3 or rl-zoo3. The zip is SB3's format (it pickles SB3's own
classes); drivestack itself never loads it: its model files stay data-only. A model's MOBIL prior
(`planner.mobil.MobilPrior`) is drivestack's decision rule, not SB3's: `DQN.predict` on the zip
decides on the bare Q-values (the CLI says so). So is an action mask: a model trained with one takes
observations that end with the safety layer's permitted commands (the zip's observation space has
them, in [0, 1]), and drivestack decides among the permitted ones only. A lane network's zip
names its features extractor, `planner.lane_network.LaneFeatures`: `DQN.load` needs drivestack
importable to open it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
from stable_baselines3 import DQN

from perception.grid import OccupancyGridBuilder
from planner.learned import LearnedAgent, load_agent
from planner.model_file import ModelFileError
from planner.model_metadata import ModelMetadata
from records import N_ACTIONS
from stack.apps.folders import check_destination, written_file
from stack.runs.model_fit import check_road_fit
from stack.training.decision_env import with_permitted
from stack.training.model import lane_features_options, warm_start


class _Spaces(gym.Env):
    """Just the spaces SB3 needs to build a model; never stepped."""

    def __init__(self, observation_space: gym.spaces.Box) -> None:
        self.observation_space, self.action_space = observation_space, gym.spaces.Discrete(N_ACTIONS)


def export_sb3(model: Path, out: Path) -> tuple[Path, ModelMetadata]:
    """Write `model` (a DDQN or DQN model file) as an SB3 `DQN` zip at `out`; returns the path and
    the model's metadata (its MOBIL prior and action mask are decision rules the zip does not hold).
    A missing model, an existing or unwritable `out`, or a model that is not a Q-network raise
    ValueError (ModelFileError) with a one-line message, before anything is written."""
    if not model.is_file():
        raise ValueError(f"{model}: no such model file")
    check_destination(out)
    agent = load_agent(model, expected_algorithms=("ddqn", "dqn"))
    if not isinstance(agent, LearnedAgent):
        raise ModelFileError(f"{model}: a Q-table has no SB3 counterpart; export a DDQN or DQN model")
    if agent.metadata.members > 1:
        raise ModelFileError(
            f"{model}: an ensemble of {agent.metadata.members} has no SB3 counterpart; export a member"
        )
    lanes = 4 if agent.metadata.lanes_count is None else agent.metadata.lanes_count
    grid = agent.grid_config
    check_road_fit(model, grid, agent.encoding, agent.observation_size, lanes, permitted=agent.sees_permitted)
    space = OccupancyGridBuilder(grid).space(agent.encoding, lanes)
    if agent.sees_permitted:
        space = with_permitted(space)
    options: dict[str, Any] = {"net_arch": list(agent.metadata.hidden)}
    if agent.metadata.kind == "lane-mlp":
        options |= lane_features_options(grid)
    sb3 = DQN("MlpPolicy", _Spaces(space), policy_kwargs=options, device="cpu", verbose=0)
    warm_start(sb3, agent)
    written = written_file(out)
    try:
        sb3.save(out)
    except OSError as error:
        written.unlink(missing_ok=True)
        raise ValueError(f"--sb3: cannot write {written} ({error.strerror})") from None
    return written, agent.metadata
