"""Sensor realism: what a fusion layer might hand the grid instead of the simulator's truth.

All effects are off by default and seeded. Applied to a `WorldState` before gridding, in order:
limited range, missed detections, position noise, false positives. The ego (row 0) is never
touched: it knows where it is.

One law, one source: `detect` is one observation's draws from one world's generator, and
`report_sensed` makes reports from draws in one compiled pass. `SensorModel.observe` calls both on
its one world; `SensorBatch` calls `detect` on each world it observes anew whose sensor is enabled
(one generator draws for one world only, so that is one short Python step per world), then
`report_sensed` once over the batch.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from common.compiled import Kernel
from records import WorldState
from records.batch import WorldBatch

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
    def law(self) -> SensorLaw:
        return SensorLaw(
            self.range_m,
            self.miss_probability,
            self.position_noise_m,
            self.false_positives,
            self.false_positive_range_m,
        )

    @property
    def enabled(self) -> bool:
        return (
            math.isfinite(self.range_m)
            or self.position_noise_m > 0
            or self.miss_probability > 0
            or self.false_positives > 0
        )


class SensorLaw(NamedTuple):
    """A `SensorConfig` as `detect` reads it (a record numba compiles too)."""

    range_m: float
    miss_probability: float
    position_noise_m: float
    false_positives: float
    false_positive_range_m: float


class Detections(NamedTuple):
    """One observation's draws: `rows` the truth rows detected (the ego's, 0, first), `noise`
    (2, rows) [m] added to their s and d when `noised` (0 on the ego's), and the false positives'
    `phantom_s` [m] and `phantom_lane`."""

    rows: np.ndarray
    noised: bool
    noise: np.ndarray
    phantom_s: np.ndarray
    phantom_lane: np.ndarray


def detect(law: SensorLaw, rng: np.random.Generator, s: np.ndarray, lanes_count: int) -> Detections:
    """What a sensor detects of vehicles at `s` [m] (row 0 the ego) on a road of `lanes_count`
    lanes, drawn from `rng` in this order: a miss per vehicle, noise on each one kept, the number
    of phantoms, their positions within +-false_positive_range_m of the ego and their lanes
    (nothing drawn for an effect that is off). Plain numpy that numba also compiles, to the same
    draws; both paths call it in Python, as each world's generator draws for that world only."""
    keep = np.abs(s - s[0]) <= law.range_m
    keep &= rng.random(len(s)) >= law.miss_probability
    keep[0] = True
    rows = np.flatnonzero(keep)
    noised = law.position_noise_m > 0
    noise = np.zeros((2, 0))
    if noised:
        noise = rng.normal(0.0, law.position_noise_m, size=(2, len(rows)))
        noise[:, 0] = 0.0
    phantoms = int(rng.poisson(law.false_positives)) if law.false_positives > 0 else 0
    phantom_s, phantom_lane = np.empty(0), np.empty(0, dtype=np.int64)
    if phantoms:
        reach = law.false_positive_range_m
        phantom_s = s[0] + rng.uniform(-reach, reach, phantoms)
        phantom_lane = rng.integers(0, lanes_count, phantoms)
    return Detections(rows, noised, noise, phantom_s, phantom_lane)


def place_draws(
    found: Detections,
    world: int,
    rows: np.ndarray,
    noised: np.ndarray,
    noise: np.ndarray,
    phantom_s: np.ndarray,
    phantom_lane: np.ndarray,
) -> int:
    """Write one observation's draws as `report_sensed` reads them, into world `world`'s row of
    each array (room for them all): the detected truth `rows` first, their `noise` (2, worlds,
    columns) [m] when `noised`, then the false positives' `phantom_s` [m] and `phantom_lane` in the
    columns after them; returns how many were detected."""
    kept, total = len(found.rows), len(found.rows) + len(found.phantom_s)
    rows[world, :kept] = found.rows
    noised[world] = found.noised
    if found.noised:
        noise[:, world, :kept] = found.noise
    phantom_s[world, kept:total] = found.phantom_s
    phantom_lane[world, kept:total] = found.phantom_lane
    return kept


class SensorModel:
    """`observe(world)`: a seeded, imperfect copy of `world`."""

    def __init__(self, config: SensorConfig, seed: int = 0) -> None:
        self.config = config
        self.rng = np.random.default_rng(seed)

    def observe(self, world: WorldState) -> WorldState:
        if not self.config.enabled:
            return world
        found = detect(self.config.law, self.rng, world.s, world.lanes_count)
        total = len(found.rows) + len(found.phantom_s)
        rows, noised = np.zeros((1, total), dtype=np.int64), np.zeros(1, dtype=bool)
        noise, phantom_s = np.zeros((2, 1, total)), np.zeros((1, total))
        phantom_lane = np.zeros((1, total), dtype=np.int64)
        kept = place_draws(found, 0, rows, noised, noise, phantom_s, phantom_lane)
        floats = np.empty((6, 1, total))
        lane = np.empty((1, total), dtype=np.result_type(world.lane, phantom_lane))
        source, phantom = np.empty((1, total), dtype=np.int64), np.empty((1, total), dtype=np.int64)
        report_sensed(
            np.array([kept]), np.array([total]), rows, noised, noise, phantom_s,
            phantom_lane, tuple(v[None] for v in (world.s, world.d, world.speed, world.heading, world.length,
            world.width)), world.lane[None], world.lane_offsets[None], floats, lane, source, phantom,
        )  # fmt: skip
        s, d, speed, heading, length, width = floats[:, 0]
        truth_rows, fake = source[0], phantom[0] >= 0
        return dataclasses.replace(
            world,
            ids=np.where(fake, PHANTOM_ID_BASE + phantom[0], world.ids[truth_rows]),
            position=np.where(fake[:, None], np.stack([s, d], axis=1), world.position[truth_rows]),
            velocity=np.where(fake[:, None], world.velocity[0], world.velocity[truth_rows]),
            crashed=world.crashed[truth_rows] & ~fake,
            s=s, d=d, speed=speed, heading=heading, length=length, width=width, lane=lane[0],
        )  # fmt: skip


@dataclasses.dataclass(frozen=True, eq=False)
class Sensed:
    """What the sensor reports of every world (`batch`, row 0 the ego) and where each reported row
    came from: `source` (worlds, rows) the truth row of a real vehicle, `phantom` (worlds, rows)
    the false positive's index in its observation (its id is `PHANTOM_ID_BASE` + it), else -1."""

    batch: WorldBatch
    source: np.ndarray
    phantom: np.ndarray


class SensorBatch:
    """`worlds` sensor models: `reset_world(world, model)` at each episode, `sense(truth, worlds)`
    after each frame (a fresh observation of the worlds flagged; the others keep their last)."""

    def __init__(self, worlds: int) -> None:
        self.models: list[SensorModel | None] = [None] * worlds
        self.enabled = np.zeros(worlds, dtype=bool)
        self.kept = np.zeros(worlds, dtype=np.int64)
        self.total = np.zeros(worlds, dtype=np.int64)
        self.source = np.zeros((worlds, 1), dtype=np.int64)
        self.noise = np.zeros((2, worlds, 1))
        self.noised = np.zeros(worlds, dtype=bool)
        self.phantom_s = np.zeros((worlds, 1))
        self.phantom_lane = np.zeros((worlds, 1), dtype=np.int64)

    def reset_world(self, world: int, model: SensorModel) -> None:
        """World `world`'s episode seen through `model` (its generator as the episode seeded it)."""
        self.models[world] = model
        self.enabled[world] = model.config.enabled

    def _room(self, rows: int) -> None:
        more = rows - self.source.shape[1]
        if more > 0:
            pad = ((0, 0), (0, more))
            self.source = np.pad(self.source, pad)
            self.noise = np.pad(self.noise, ((0, 0), *pad))
            self.phantom_s, self.phantom_lane = np.pad(self.phantom_s, pad), np.pad(self.phantom_lane, pad)

    def _draw(self, world: int, truth: WorldBatch) -> None:
        """World `world`'s draws (`detect`), as its `SensorModel.observe` draws them (a world whose
        sensor is enabled)."""
        model = self.models[world]
        assert model is not None
        n = int(truth.count[world])
        found = detect(model.config.law, model.rng, truth.s[world, :n], int(truth.lanes_count[world]))
        total = len(found.rows) + len(found.phantom_s)
        if total > self.source.shape[1]:
            self._room(total)
        self.kept[world] = place_draws(
            found, world, self.source, self.noised, self.noise, self.phantom_s, self.phantom_lane
        )
        self.total[world] = total

    def sense(self, truth: WorldBatch, worlds: np.ndarray) -> Sensed:
        """Every world as its sensor reports it, observing the worlds flagged in `worlds` anew."""
        self._room(truth.s.shape[1])
        flagged = np.asarray(worlds, dtype=bool)
        whole = flagged & ~self.enabled
        self.kept[whole] = self.total[whole] = truth.count[whole]
        self.source[whole] = np.arange(self.source.shape[1])
        self.noised[whole] = False
        for world in np.flatnonzero(flagged & self.enabled).tolist():
            self._draw(world, truth)
        rows = int(self.total.max())
        floats = np.empty((6, len(self.total), rows))
        lane = np.empty((len(self.total), rows), dtype=np.result_type(truth.lane, self.phantom_lane))
        source = np.empty((len(self.total), rows), dtype=np.int64)
        phantom = np.empty_like(source)
        report_sensed(
            self.kept, self.total, self.source, self.noised, self.noise, self.phantom_s, self.phantom_lane,
            (truth.s, truth.d, truth.speed, truth.heading, truth.length, truth.width), truth.lane,
            truth.lane_offsets, floats, lane, source, phantom,
        )  # fmt: skip
        s, d, speed, heading, length, width = floats
        batch = dataclasses.replace(
            truth, count=self.total.copy(), s=s, d=d, speed=speed, heading=heading, length=length,
            width=width, lane=lane,
        )  # fmt: skip
        return Sensed(batch, source, phantom)


@Kernel
def report_sensed(
    kept: np.ndarray,
    total: np.ndarray,
    rows: np.ndarray,
    noised: np.ndarray,
    noise: np.ndarray,
    phantom_s: np.ndarray,
    phantom_lane: np.ndarray,
    truth: tuple[np.ndarray, ...],
    truth_lane: np.ndarray,
    lane_offsets: np.ndarray,
    floats_out: np.ndarray,
    lane_out: np.ndarray,
    source_out: np.ndarray,
    phantom_out: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through SensorBatch.sense
    """Each world's report from its draws (`SensorBatch`): its `kept[w]` detected truth `rows`
    (s and d plus `noise` when `noised[w]`), then its false positives to `total[w]` (at
    `phantom_s`, on the centre of `phantom_lane`, with the ego's speed, heading and size), zeros
    past them. `truth` is (s, d, speed, heading, length, width); `floats_out` (6, worlds, columns)
    those of the report, `lane_out` its lanes, `source_out` each row's truth row (0 past the
    detected), `phantom_out` each false positive's index (-1 for the others)."""
    for w in range(floats_out.shape[1]):
        for c in range(floats_out.shape[2]):
            real = c < kept[w]
            fake = not real and c < total[w]
            source = rows[w, c] if real else 0
            source_out[w, c] = source
            phantom_out[w, c] = c - kept[w] if fake else -1
            for f in range(6):
                floats_out[f, w, c] = truth[f][w, source] if real else 0.0
            lane_out[w, c] = truth_lane[w, source] if real else 0
            if real and noised[w]:
                floats_out[0, w, c] += noise[0, w, c]
                floats_out[1, w, c] += noise[1, w, c]
            if fake:
                floats_out[0, w, c] = phantom_s[w, c]
                floats_out[1, w, c] = lane_offsets[w, phantom_lane[w, c]]
                for f in range(2, 6):
                    floats_out[f, w, c] = truth[f][w, 0]
                lane_out[w, c] = phantom_lane[w, c]
