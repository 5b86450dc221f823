"""The occupancy grid an agent is shown: perception builds it, the planner decodes it."""

from __future__ import annotations

import math
from typing import Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, model_validator

MAX_SPEED = 40.0
"""Speed that the grid's `ego_speed` feature maps to 1 [m/s] (highway-env's Vehicle.MAX_SPEED)."""
EGO_HEADING_SCALE = 0.2
"""Heading error to the lane [rad] that the grid's `ego_lateral` feature maps to 1."""
TRAFFIC_VALUES = 3
"""Values of the `traffic` feature per grid row."""
SIDE_LANES_SEEN = 2
"""`lane_code: sides` counts the lanes on each side of the ego up to this many."""

Feature = Literal["relative_speed", "ttc", "ego_speed", "ego_lateral", "traffic"]
FEATURES: tuple[Feature, ...] = get_args(Feature)
"""The grid's optional features, in the order the observation lays them out."""


class GridConfig(BaseModel):
    """The occupancy grid an agent decides on (built by `perception.grid`). Lengths in m, speeds
    in m/s, times in s."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    cell_length: float = Field(5.0, ge=0.5, le=50, description="cell length [m]")
    cells_ahead: int = Field(9, ge=1, le=200, description="line of sight in cells, the ego's own included")
    cells_behind: int = Field(4, ge=0, le=200)
    lanes: Literal["absolute", "ego"] = "absolute"
    lateral_reach: int = Field(1, ge=1, le=8, description="ego mode: neighbour lanes on each side")
    footprint: bool = True
    features: tuple[Feature, ...] = Field(
        (), max_length=len(FEATURES), description="optional features, each at most once"
    )
    speed_scale: float = Field(20.0, ge=0.1, le=100, description="relative speed giving feature 1 [m/s]")
    ttc_horizon: float = Field(10.0, ge=0.1, le=100, description="time-to-collision giving feature 1 [s]")
    lane_code: Literal["binary", "sides"] = Field(
        "binary",
        description="where the ego is: its lane index in binary (the paper's; its size grows with the "
        "lane count) or, ego mode only, the lanes to its left and right (any lane count)",
    )

    @model_validator(mode="after")
    def _features_once(self) -> GridConfig:
        if len(set(self.features)) != len(self.features):
            raise ValueError("features: each feature at most once")
        return self

    @model_validator(mode="after")
    def _sides_need_ego_rows(self) -> GridConfig:
        if self.lane_code == "sides" and self.lanes != "ego":
            raise ValueError("lane_code: sides needs lanes: ego (absolute rows grow with the lane count)")
        return self

    @property
    def cells(self) -> int:
        return self.cells_behind + self.cells_ahead

    @property
    def ego_column(self) -> int:
        return self.cells_behind

    def rows(self, lanes_count: int) -> int:
        return lanes_count if self.lanes == "absolute" else 2 * self.lateral_reach + 1

    def observation_layout(self, lanes_count: int) -> list[tuple[str, int]]:
        """The observation encoding's parts in order as (name, values): presence, each enabled
        feature in FEATURES' order, the lane part."""
        rows, cells = self.rows(lanes_count), self.cells
        sizes = {
            "relative_speed": rows * cells,
            "ttc": rows,
            "ego_speed": 1,
            "ego_lateral": 2,
            "traffic": rows * TRAFFIC_VALUES,
        }
        enabled = [(name, sizes[name]) for name in FEATURES if name in self.features]
        return [("presence", rows * cells), *enabled, ("lane", self.lane_code_size(lanes_count))]

    def observation_parts(self, lanes_count: int) -> dict[str, slice]:
        """Each part of `observation_layout`'s columns in the observation."""
        parts, start = {}, 0
        for name, size in self.observation_layout(lanes_count):
            parts[name], start = slice(start, start + size), start + size
        return parts

    def lane_code_size(self, lanes_count: int) -> int:
        """Values of the ego-lane part of the paper and observation encodings."""
        return lane_code_bits(lanes_count) if self.lane_code == "binary" else 2


MAX_LANES = 10
"""Most lanes a road may have."""


def lane_code_bits(lanes: int) -> int:
    """Bits of the binary ego-lane code (the paper's encoding)."""
    return max(1, math.ceil(math.log2(lanes)))
