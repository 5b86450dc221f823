"""The lane network: a Q-network that reads the occupancy grid lane by lane. Every row (the ego's
lane and `lateral_reach` on each side: its presence, relative speeds, TTC) goes through one small
MLP shared by all rows (`LANE_ENCODER`), so what it learns about a gap or a slow car in one lane
holds in every lane; the rows' codes, in their order, and the ego's own values (speed, where it is,
the permitted commands) feed the head, an MLP to one Q-value per command.

`LaneFeatures` is an SB3 features extractor (training builds it through `policy_kwargs`, and SB3's
own MLP is the head); `LaneQNetwork` is the same function at inference, its arrays named
`features.*` and `head.*` (`planner.networks.lane_network_shapes`)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, create_mlp
from torch import nn

from planner.networks import LANE_ENCODER, lane_columns
from records import N_ACTIONS, GridConfig


class LaneFeatures(BaseFeaturesExtractor):
    """Each grid row of the observation through the shared lane encoder, the codes concatenated
    row by row, then the observation's other values."""

    def __init__(self, observation_space: gym.spaces.Box, grid: GridConfig) -> None:
        row_columns, rest = lane_columns(grid, int(np.prod(observation_space.shape)))
        super().__init__(observation_space, row_columns.shape[0] * LANE_ENCODER[-1] + rest.size)
        layers = create_mlp(row_columns.shape[1], LANE_ENCODER[-1], list(LANE_ENCODER[:-1]))
        self.encoder = nn.Sequential(*layers, nn.ReLU())
        self.row_columns = th.as_tensor(row_columns)
        self.rest = th.as_tensor(rest)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        lanes = self.encoder(observations[:, self.row_columns])
        return th.cat([lanes.flatten(1), observations[:, self.rest]], dim=1)


class LaneQNetwork(nn.Module):
    """`LaneFeatures` then the head (hidden widths `head`, ReLU between): Q-values per command."""

    def __init__(self, grid: GridConfig, observation_size: int, head: list[int]) -> None:
        super().__init__()
        space = gym.spaces.Box(-1.0, 1.0, (observation_size,), dtype=np.float32)
        self.features = LaneFeatures(space, grid)
        self.head = nn.Sequential(*create_mlp(self.features.features_dim, N_ACTIONS, head))

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.head(self.features(observations))
