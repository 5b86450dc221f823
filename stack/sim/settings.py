"""Settings of the simulator: the highway-env road and which backend runs it (no highway-env
import here, so configs load fast)."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

from records import BACKENDS, Backend, one_of


class HighwayConfig(BaseModel):
    """The section handed to `gym.make("highway-v0", config=...)`."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    lanes_count: int = Field(4, ge=1, le=10)
    vehicles_count: int = Field(50, ge=0, le=500)
    vehicles_density: float = Field(1.0, gt=0)
    duration: float = Field(40.0, gt=0, description="episode length [s]")
    simulation_frequency: int = Field(15, ge=1, le=1000, description="physics rate [Hz]")


class SimConfig(BaseModel):
    """Which highway-env road runs the physics: `fast` (indexed, identical trajectories) or `stock`."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    backend: Annotated[Backend, one_of("backend", BACKENDS)] = "fast"
