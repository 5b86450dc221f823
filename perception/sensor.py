"""Sensor realism: what a fusion layer might hand the grid instead of the simulator's truth.

All effects are off by default and seeded. Applied to a `WorldState` before gridding, in order:
limited range, missed detections, position noise, false positives. The ego (row 0) is never
touched: it knows where it is.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from records import WorldState

PHANTOM_ID_BASE = 1_000_000
"""Ids of false-positive detections start here, so they never collide with real vehicles."""
MAX_RANGE_M = 10_000.0
"""Longest finite sensor range [m]; `.inf` (the default) is unlimited."""


class SensorConfig(BaseModel):
    """Noise model. Distances in m; probabilities per vehicle per observation."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    range_m: float = Field(
        math.inf, gt=0, description="vehicles farther than this (|ds|) are not seen [m]; .inf: unlimited"
    )
    position_noise_m: float = Field(0.0, ge=0, le=100, description="std of Gaussian noise on s and d [m]")
    miss_probability: float = Field(0.0, ge=0, le=1, description="chance a vehicle is not detected")
    false_positives: float = Field(
        0.0, ge=0, le=100, description="mean phantom vehicles per observation (Poisson)"
    )
    false_positive_range_m: float = Field(
        60.0, gt=0, le=1000, description="phantoms appear within +-this of the ego [m]"
    )

    @field_validator("range_m")
    @classmethod
    def _finite_or_unlimited(cls, range_m: float) -> float:
        if math.isfinite(range_m) and range_m > MAX_RANGE_M:
            raise ValueError(f"must be at most {MAX_RANGE_M:g} m, or .inf (unlimited), got {range_m:g}")
        return range_m

    @property
    def enabled(self) -> bool:
        return (
            math.isfinite(self.range_m)
            or self.position_noise_m > 0
            or self.miss_probability > 0
            or self.false_positives > 0
        )


class SensorModel:
    """`observe(world)`: a seeded, imperfect copy of `world`."""

    def __init__(self, config: SensorConfig, seed: int = 0) -> None:
        self.config = config
        self.rng = np.random.default_rng(seed)

    def observe(self, world: WorldState) -> WorldState:
        if not self.config.enabled:
            return world
        config, rng = self.config, self.rng
        n = world.count
        keep = np.abs(world.s - world.s[0]) <= config.range_m
        keep &= rng.random(n) >= config.miss_probability
        keep[0] = True
        rows = np.flatnonzero(keep)
        fields = {
            name: getattr(world, name)[rows]
            for name in (
                "ids",
                "position",
                "heading",
                "speed",
                "velocity",
                "lane",
                "length",
                "width",
                "s",
                "d",
                "crashed",
            )
        }
        if config.position_noise_m > 0:
            noise = rng.normal(0.0, config.position_noise_m, size=(2, len(rows)))
            noise[:, 0] = 0.0
            fields["s"] = fields["s"] + noise[0]
            fields["d"] = fields["d"] + noise[1]
        phantoms = rng.poisson(config.false_positives) if config.false_positives > 0 else 0
        if phantoms:
            fields = _with_phantoms(fields, world, phantoms, config.false_positive_range_m, rng)
        return dataclasses.replace(world, **fields)


def _with_phantoms(
    fields: dict[str, np.ndarray], world: WorldState, count: int, reach: float, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """Append `count` phantom vehicles at uniform positions on the road, at the ego's speed."""
    s = world.s[0] + rng.uniform(-reach, reach, count)
    lanes = rng.integers(0, world.lanes_count, count)
    d = world.lane_offsets[lanes]
    phantom = {
        "ids": PHANTOM_ID_BASE + np.arange(count),
        "position": np.stack([s, d], axis=1),
        "heading": np.zeros(count),
        "speed": np.full(count, world.speed[0]),
        "velocity": np.tile(world.velocity[0], (count, 1)),
        "lane": lanes,
        "length": np.full(count, world.length[0]),
        "width": np.full(count, world.width[0]),
        "s": s,
        "d": d,
        "crashed": np.zeros(count, dtype=bool),
    }
    return {name: np.concatenate([fields[name], phantom[name]]) for name in fields}
