"""Many worlds' snapshots as one record: the batched path's counterpart of `WorldState`."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import NamedTuple

import numpy as np

from records.world import WorldState


class BatchColumns(NamedTuple):
    """The [worlds, vehicles] arrays a compiled kernel takes as one record (`WorldBatch.columns`);
    `vehicles` is each world's `count`."""

    vehicles: np.ndarray
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    lane: np.ndarray
    lanes_count: np.ndarray
    lane_offsets: np.ndarray


@dataclass(frozen=True)
class WorldBatch:
    """W worlds at one control tick as [worlds, vehicles] arrays; in every world row 0 is the ego
    and rows at or past `count[w]` are padding (zeros, never read). `s` and `d` [m] are in the
    frame of lane 0 of the ego's road segment, as in `WorldState`; `lane_offsets[w, k]` is lane
    k's centre (padding past `lanes_count[w]`); `lane_heading[w]` is lane 0's heading at the ego
    [rad]; every lane is `lane_width` [m] wide (highway-env's roads: one width)."""

    count: np.ndarray
    s: np.ndarray
    d: np.ndarray
    speed: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    lane: np.ndarray
    lanes_count: np.ndarray
    lane_offsets: np.ndarray
    lane_heading: np.ndarray
    lane_width: float

    @property
    def worlds(self) -> int:
        return len(self.count)

    def columns(self) -> BatchColumns:
        """The arrays a compiled kernel takes as one record."""
        return BatchColumns(
            self.count,
            self.s,
            self.d,
            self.speed,
            self.length,
            self.width,
            self.lane,
            self.lanes_count,
            self.lane_offsets,
        )

    def rows(self, worlds: np.ndarray) -> WorldBatch:
        """The worlds `worlds` (indices, in that order) as a batch of their own."""
        arrays = [field.name for field in fields(self) if field.name != "lane_width"]
        return replace(self, **{name: getattr(self, name)[worlds] for name in arrays})

    @classmethod
    def of(cls, worlds: list[WorldState]) -> WorldBatch:
        """The snapshots `worlds` stacked (padded to the largest vehicle and lane counts)."""
        vehicles = max(world.count for world in worlds)
        lanes = max(world.lanes_count for world in worlds)
        widths = {world.lane_width for world in worlds}
        if len(widths) != 1:
            raise ValueError(f"a batch's roads share one lane width, got {sorted(widths)} m")

        def padded(name: str, dtype: type) -> np.ndarray:
            stacked: np.ndarray = np.zeros((len(worlds), vehicles), dtype=dtype)
            for row, world in enumerate(worlds):
                stacked[row, : world.count] = getattr(world, name)
            return stacked

        offsets = np.zeros((len(worlds), lanes))
        for row, world in enumerate(worlds):
            offsets[row, : world.lanes_count] = world.lane_offsets
        return cls(
            count=np.array([world.count for world in worlds], dtype=np.int64),
            s=padded("s", np.float64),
            d=padded("d", np.float64),
            speed=padded("speed", np.float64),
            heading=padded("heading", np.float64),
            length=padded("length", np.float64),
            width=padded("width", np.float64),
            lane=padded("lane", np.int64),
            lanes_count=np.array([world.lanes_count for world in worlds], dtype=np.int64),
            lane_offsets=offsets,
            lane_heading=np.array([world.lanes[0].heading_at(float(world.s[0])) for world in worlds]),
            lane_width=widths.pop(),
        )
