"""The lookahead agent's settings (`planner.lookahead` in the run config): its horizon, its score's
weights and gates, its hysteresis. Light to import (pydantic only), so the run config can hold it."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator


class LookaheadConfig(BaseModel):
    """Horizons and times in s, TTCs in s; the weights are relative (they are normalised), the
    margin is in units of the normalised score [0, 1]."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    horizon_s: float = Field(8.0, ge=1.0, le=15.0, description="how far each command is rolled out [s]")
    step_s: float = Field(0.25, ge=0.02, le=1.0, description="rollout step [s]")
    terminal_s: float = Field(
        2.0,
        ge=0,
        le=30,
        description="progress counts, beyond the horizon, this times the end speed or, for a change, "
        "the discounted speed the lane beyond its target offers, whichever is higher [s]",
    )
    option_discount: float = Field(
        0.8, ge=0, le=1, description="what the lane beyond a change's target is worth against being in it"
    )
    weight_progress: float = Field(5.0, ge=0, le=100, description="weight of progress along the road")
    weight_ttc: float = Field(5.0, ge=0, le=100, description="weight of the time-to-collision score")
    weight_comfort: float = Field(2.0, ge=0, le=100, description="weight of the comfort score")
    ttc_floor_s: float = Field(
        1.0, ge=0, le=10, description="a rollout whose TTC falls below this is gated [s]"
    )
    ttc_good_s: float = Field(3.0, gt=0, le=30, description="TTC from which the TTC score is 1 [s]")
    margin: float = Field(
        0.02, ge=0, le=1, description="a lane change must beat staying by this much of the score"
    )
    comfort_lateral_mps2: float = Field(2.0, gt=0, le=20, description="lateral acceleration bound [m/s^2]")
    comfort_lateral_jerk_mps3: float = Field(2.5, gt=0, le=50, description="lateral jerk bound [m/s^3]")

    @model_validator(mode="after")
    def _weights_and_ttc(self) -> LookaheadConfig:
        if self.weight_progress + self.weight_ttc + self.weight_comfort <= 0:
            raise ValueError("weight_progress: at least one weight must be positive")
        if self.ttc_good_s <= self.ttc_floor_s:
            raise ValueError(
                f"ttc_good_s: must exceed ttc_floor_s ({self.ttc_floor_s}), got {self.ttc_good_s}"
            )
        if self.step_s > self.horizon_s:
            raise ValueError(f"step_s: must be at most horizon_s ({self.horizon_s}), got {self.step_s}")
        return self
