"""The sensor model of many worlds at once: each world's perceived snapshot as its own
`SensorModel.observe` makes it from that world's truth, to the same bits.

Each world keeps its `SensorModel` (its generator, seeded per episode as the per-world loop seeds
it). A world's draws are the per-world code's, in its order and sizes (misses over every vehicle,
then noise on the kept rows, then the phantom count, positions and lanes): that is one short
Python step per world sensed, because one generator cannot draw for another. What is made of the
draws (the kept rows gathered, noise added, phantoms appended) runs in numpy over the batch, the
same element-wise operations as the per-world code's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from perception.sensor import SensorModel
from records.batch import WorldBatch


@dataclass(frozen=True, eq=False)
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
        self.settings: list[tuple[float, float, float, float] | None] = [None] * worlds
        self.ranges = np.full(worlds, np.inf)
        self.kept = np.zeros(worlds, dtype=np.int64)
        self.total = np.zeros(worlds, dtype=np.int64)
        self.source = np.zeros((worlds, 1), dtype=np.int64)
        self.noise = np.zeros((2, worlds, 1))
        self.noised = np.zeros(worlds, dtype=bool)
        self.phantom_s = np.zeros((worlds, 1))
        self.phantom_lane = np.zeros((worlds, 1), dtype=np.int64)

    def reset_world(self, world: int, model: SensorModel) -> None:
        """World `world`'s episode seen through `model` (its generator as the episode seeded it)."""
        config = model.config
        self.models[world] = model
        self.ranges[world] = config.range_m
        self.settings[world] = (
            (
                config.miss_probability,
                config.position_noise_m,
                config.false_positives,
                config.false_positive_range_m,
            )
            if config.enabled
            else None
        )

    def _room(self, rows: int) -> None:
        more = rows - self.source.shape[1]
        if more > 0:
            pad = ((0, 0), (0, more))
            self.source = np.pad(self.source, pad)
            self.noise = np.pad(self.noise, ((0, 0), *pad))
            self.phantom_s, self.phantom_lane = np.pad(self.phantom_s, pad), np.pad(self.phantom_lane, pad)

    def _draw(self, world: int, truth: WorldBatch, in_range: np.ndarray) -> None:
        """World `world`'s draws, as `SensorModel.observe` draws them from its truth."""
        model, settings = self.models[world], self.settings[world]
        n = int(truth.count[world])
        if model is None or settings is None:
            self.kept[world] = self.total[world] = n
            self.source[world, :n] = np.arange(n)
            self.noised[world] = False
            return
        miss, noise_m, false_positives, reach = settings
        rng = model.rng
        keep = rng.random(n) >= miss
        keep &= in_range[world, :n]
        keep[0] = True
        rows = keep.nonzero()[0]
        kept = len(rows)
        noise = rng.normal(0.0, noise_m, size=(2, kept)) if noise_m > 0 else None
        phantoms = int(rng.poisson(false_positives)) if false_positives > 0 else 0
        if kept + phantoms > self.source.shape[1]:
            self._room(kept + phantoms)
        self.source[world, :kept] = rows
        self.noised[world] = noise is not None
        if noise is not None:
            noise[:, 0] = 0.0
            self.noise[:, world, :kept] = noise
        if phantoms:
            added = slice(kept, kept + phantoms)
            self.phantom_s[world, added] = truth.s[world, 0] + rng.uniform(-reach, reach, phantoms)
            self.phantom_lane[world, added] = rng.integers(0, int(truth.lanes_count[world]), phantoms)
        self.kept[world], self.total[world] = kept, kept + phantoms

    def sense(self, truth: WorldBatch, worlds: np.ndarray) -> Sensed:
        """Every world as its sensor reports it, observing the worlds flagged in `worlds` anew."""
        self._room(truth.s.shape[1])
        in_range = np.abs(truth.s - truth.s[:, :1]) <= self.ranges[:, None]
        for world in np.flatnonzero(worlds).tolist():
            self._draw(world, truth, in_range)
        rows = int(self.total.max())
        column = np.arange(rows)[None, :]
        real = column < self.kept[:, None]
        phantom = (column >= self.kept[:, None]) & (column < self.total[:, None])
        source = np.where(real, self.source[:, :rows], 0)
        floats = np.stack([truth.s, truth.d, truth.speed, truth.heading, truth.length, truth.width])
        s, d, speed, heading, length, width = np.where(
            real, np.take_along_axis(floats, source[None], axis=2), 0.0
        )
        noised = self.noised[:, None] & real
        s = np.where(noised, s + self.noise[0, :, :rows], s)
        d = np.where(noised, d + self.noise[1, :, :rows], d)
        lanes = self.phantom_lane[:, :rows]
        phantom_d = np.take_along_axis(truth.lane_offsets, np.where(phantom, lanes, 0), axis=1)
        lane = np.where(real, np.take_along_axis(truth.lane, source, axis=1), 0)
        batch = replace(
            truth,
            count=self.total.copy(),
            s=np.where(phantom, self.phantom_s[:, :rows], s),
            d=np.where(phantom, phantom_d, d),
            speed=np.where(phantom, truth.speed[:, :1], speed),
            heading=heading,
            length=np.where(phantom, truth.length[:, :1], length),
            width=np.where(phantom, truth.width[:, :1], width),
            lane=np.where(phantom, lanes, lane),
        )
        return Sensed(batch, source, np.where(phantom, column - self.kept[:, None], -1))
