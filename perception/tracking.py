"""Perception that tracks: a sensor's detections become tracks before the grid, the safety layer or
emergency braking see them. `Tracker.update(detected, dt)` turns one frame's detections
(`perception.sensor`) into the world of the confirmed tracks: row 0 the ego as detected, then each
confirmed track in slot order at its filtered s and d, its heading its last detection's, its
speed the filtered velocity's component along that heading (so relative speeds and times to
collision come from the filter), its size from its last detection, its id `TRACK_ID_BASE` + a
counter. One frame's phantom is never confirmed; a missed detection coasts the track
(`perception.tracking_law`, the per-frame law).

One law, two paths: `Tracker` calls `track_world` compiled on its world; `TrackerBatch` calls
`track_worlds` on the worlds of a batch, then makes every world's tracked rows in numpy over the
batch, to the bits `Tracker.update` reports.

Before the first frame the sensor has run for `confirm_frames` observations of the first world
(`warm_up`; the world frozen, dt = 0), so an episode starts with its vehicles tracked rather
than with an empty road."""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from perception.sensor import SensorConfig
from perception.track_records import (
    COVARIANCE_SIZE,
    ROW_FIELDS,
    STATE_SIZE,
    MeasuredWorlds,
    TrackerLaw,
    Tracks,
)
from perception.tracking_kernels import (
    WORLD_FLOATS,
    WORLD_INTEGERS,
    report_worlds,
    track_world,
    track_worlds,
)
from perception.tracking_law import work_size
from records import WorldState
from records.batch import WorldBatch

TRACK_ID_BASE = 2_000_000
"""Ids of tracks start here, so they never collide with real vehicles' or phantoms' ids."""
MIN_POSITION_NOISE_M = 0.1
"""The position noise the filter assumes of a sensor that reports none [m]."""


class TrackerConfig(BaseModel):
    """`perception.tracker`: whether the perceived world is tracked (`mode`: `auto` tracks whenever
    the episode's sensor is imperfect, `on` always, `off` never: every layer then acts on each
    frame's raw detections), and the tracker's settings."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    mode: Literal["auto", "on", "off"] = "auto"
    confirm_hits: int = Field(4, ge=1, le=62, description="detections in the last confirm_frames to confirm")
    confirm_frames: int = Field(5, ge=1, le=62, description="frames of the confirmation window")
    coast_frames: int = Field(5, ge=1, le=1000, description="missed frames running that delete a track")
    gate: float = Field(
        13.3, gt=0, le=1000, description="squared Mahalanobis gate (4 degrees of freedom: 99 %)"
    )
    longitudinal_acceleration_mps2: float = Field(
        3.0, gt=0, le=100, description="white-noise acceleration along the lane [m/s^2]"
    )
    lateral_acceleration_mps2: float = Field(
        1.0, gt=0, le=100, description="white-noise acceleration across the lane [m/s^2]"
    )
    speed_noise_mps: float = Field(
        0.5, gt=0, le=100, description="std of a detection's reported velocity, each direction [m/s]"
    )
    max_tracks: int = Field(
        128, ge=1, le=4096, description="tracks a world (more detections are not tracked)"
    )

    @field_validator("mode", mode="before")
    @classmethod
    def _yaml_switch(cls, mode: object) -> object:
        """YAML reads a bare `on` / `off` as true / false."""
        return {True: "on", False: "off"}.get(mode, mode) if isinstance(mode, bool) else mode

    @model_validator(mode="after")
    def _hits_fit_the_window(self) -> TrackerConfig:
        if self.confirm_hits > self.confirm_frames:
            raise ValueError(
                f"confirm_hits ({self.confirm_hits}) must be at most confirm_frames ({self.confirm_frames})"
            )
        return self

    @property
    def law(self) -> TrackerLaw:
        return TrackerLaw(
            self.confirm_hits,
            self.confirm_frames,
            self.coast_frames,
            float(self.gate),
            float(self.longitudinal_acceleration_mps2),
            float(self.lateral_acceleration_mps2),
            float(self.speed_noise_mps) ** 2,
        )

    def tracks(self, sensor: SensorConfig) -> bool:
        """Whether an episode seen through `sensor` is tracked."""
        return self.mode == "on" or (self.mode == "auto" and sensor.enabled)


def position_variance(sensor: SensorConfig) -> float:
    """The variance the filter assumes of a detection's s and d through `sensor` [m^2]."""
    return max(sensor.position_noise_m, MIN_POSITION_NOISE_M) ** 2


def empty_tracks(slots: int, worlds: tuple[int, ...] = ()) -> Tracks:
    """`slots` free track slots (a world's, or with `worlds` (W,) each world's)."""
    return Tracks(
        np.zeros((*worlds, slots, STATE_SIZE)),
        np.zeros((*worlds, slots, COVARIANCE_SIZE)),
        np.zeros((*worlds, slots), dtype=np.int64),
        np.zeros((*worlds, slots), dtype=np.int64),
        np.zeros((*worlds, slots), dtype=np.int64),
        np.zeros((*worlds, slots), dtype=np.int64),
        np.zeros((*worlds, slots), dtype=np.int64),
        np.zeros((*worlds, slots, 3)),
        np.full((*worlds, 1), TRACK_ID_BASE, dtype=np.int64),
    )


def lane_velocity(
    speed: np.ndarray, heading: np.ndarray, lane_heading: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Detections' reported velocity along and across the lane heading at the ego `lane_heading`
    [rad], from their `speed` [m/s] and `heading` [rad], and their heading to the lane [rad]
    (numpy's cosine and sine: one element's bits on any array)."""
    relative = np.asarray(heading - lane_heading)
    return np.asarray(speed * np.cos(relative)), np.asarray(speed * np.sin(relative)), relative


def _floats(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64)


class TrackerWork:
    """The law's work buffers (`perception.tracking_law.work_size`), kept across frames and grown
    when a frame has more detections than any before, so a frame allocates none."""

    def __init__(self, slots: int) -> None:
        self.slots, self.detections = slots, -1
        self.integers, self.floats = np.empty(0, dtype=np.int64), np.empty(0)

    def fit(self, detections: int) -> TrackerWork:
        """Room for `detections` detections (rows past the ego)."""
        detections = max(detections, 0)
        if detections > self.detections:
            self.detections = detections
            integers, floats = work_size(self.slots, detections)
            self.integers, self.floats = np.empty(integers, dtype=np.int64), np.empty(floats)
        return self


class Tracker:
    """One world's tracker: `warm_up(observe)` at an episode's start, then `update(detected, dt)`
    every frame."""

    def __init__(self, config: TrackerConfig, sensor: SensorConfig) -> None:
        self.config, self.law = config, config.law
        self.position_variance = position_variance(sensor)
        self.tracks = empty_tracks(config.max_tracks)
        self.work = TrackerWork(config.max_tracks)
        self.columns = config.max_tracks + 1
        """Rows a tracked world can have: the ego and every track."""

    def warm_up(self, detections: list[WorldState]) -> WorldState:
        """The tracked world after `detections`, the sensor's observations of the frozen first world."""
        tracked = detections[0]
        for detected in detections:
            tracked = self.update(detected, 0.0)
        return tracked

    def update(self, detected: WorldState, dt: float) -> WorldState:
        """The world of the confirmed tracks after the frame `detected`, `dt` [s] after the last:
        `track_world` writes it into two fresh buffers, each field a slice of them (built
        directly: `dataclasses.replace` costs twice as much; the other fields are `detected`'s)."""
        lane_heading = detected.lanes[0].heading_at(float(detected.s[0]))
        along, across, relative = lane_velocity(detected.speed, detected.heading, lane_heading)
        columns = self.columns
        floats = np.empty(WORLD_FLOATS * columns)
        integers = np.empty(WORLD_INTEGERS * columns, dtype=np.int64)
        work = self.work.fit(detected.count - 1)
        count = track_world(
            *self.law, *self.tracks,
            detected.count, detected.s, detected.d, along, across, detected.length, detected.width, relative,
            self.position_variance, dt, detected.lane_offsets, detected.lanes_count, float(lane_heading),
            detected.ids, detected.lane, detected.position, detected.velocity, detected.heading,
            detected.speed, floats, integers, work.integers, work.floats,
        )  # fmt: skip
        rows = count + 1
        pairs = floats[: 4 * columns].reshape(2, columns, 2)
        fields = floats[4 * columns :].reshape(6, columns)
        crashed = np.zeros(rows, dtype=bool)
        crashed[0] = detected.crashed[0]
        return WorldState(
            time=detected.time,
            ids=integers[:rows],
            position=pairs[0, :rows],
            heading=fields[0, :rows],
            speed=fields[1, :rows],
            velocity=pairs[1, :rows],
            lane=integers[columns : columns + rows],
            length=fields[2, :rows],
            width=fields[3, :rows],
            s=fields[4, :rows],
            d=fields[5, :rows],
            crashed=crashed,
            lanes=detected.lanes,
            lane_offsets=detected.lane_offsets,
            ego_lateral_speed=detected.ego_lateral_speed,
            ego_yaw_rate=detected.ego_yaw_rate,
        )


@dataclasses.dataclass(frozen=True, eq=False)
class TrackedBatch:
    """What the tracker reports of every world (`batch`, row 0 the ego) and each row's track slot
    (`slot` (worlds, rows), -1 on the ego's row and on the rows of untracked worlds)."""

    batch: WorldBatch
    slot: np.ndarray


class TrackerBatch:
    """`worlds` trackers of one config: `reset_world(world, sensor)` at each episode (untracked when
    `config.tracks(sensor)` is false: the world's detections pass through), `update(sensed,
    worlds, dt)` after each frame (the worlds flagged track their new detections; the others
    keep their tracks)."""

    def __init__(self, config: TrackerConfig, worlds: int) -> None:
        self.config, self.law = config, config.law
        slots = config.max_tracks
        self.tracks = empty_tracks(slots, (worlds,))
        self.tracked = np.zeros(worlds, dtype=bool)
        self.position_variance = np.ones(worlds)
        self.slots = np.zeros((worlds, slots), dtype=np.int64)
        self.lanes = np.zeros((worlds, slots), dtype=np.int64)
        self.rows = np.zeros((worlds, slots, ROW_FIELDS))
        self.counts = np.zeros(worlds, dtype=np.int64)
        self.work = TrackerWork(slots)

    def reset_world(self, world: int, sensor: SensorConfig) -> None:
        """World `world`'s episode seen through `sensor`: its tracks cleared."""
        self.tracked[world] = self.config.tracks(sensor)
        self.position_variance[world] = position_variance(sensor)
        for array in self.tracks:
            array[world] = 0
        self.tracks.next_ident[world] = TRACK_ID_BASE
        self.counts[world] = 0

    def update(self, sensed: WorldBatch, worlds: np.ndarray, dt: float) -> TrackedBatch:
        """Every world as its tracker reports it after the frame `sensed`, `dt` [s] after the last,
        tracking the detections of the tracked worlds flagged in `worlds`."""
        flagged = np.asarray(worlds, dtype=bool) & self.tracked
        along, across, relative = lane_velocity(sensed.speed, sensed.heading, sensed.lane_heading[:, None])
        found = MeasuredWorlds(
            sensed.count, sensed.s, sensed.d, along, across, sensed.length, sensed.width, relative
        )
        work = self.work.fit(sensed.s.shape[1] - 1)
        track_worlds(
            self.law, self.tracks, found, self.position_variance, dt, flagged, sensed.lane_offsets,
            sensed.lanes_count, _floats(sensed.lane_heading), self.slots, self.lanes, self.rows, self.counts,
            work.integers, work.floats,
        )  # fmt: skip
        return self._report(sensed)

    def _report(self, sensed: WorldBatch) -> TrackedBatch:
        """The tracked worlds' rows (ego, then confirmed tracks), the others' detections
        (`report_worlds`, compiled)."""
        columns = max(sensed.s.shape[1], 1 + int(self.counts.max(initial=0)))
        names = ("s", "d", "speed", "heading", "length", "width")
        detected = tuple(_floats(getattr(sensed, name)) for name in names)
        out = np.empty((len(names), sensed.worlds, columns))
        lane = np.empty((sensed.worlds, columns), dtype=sensed.lane.dtype)
        slot = np.empty((sensed.worlds, columns), dtype=np.int64)
        report_worlds(
            self.tracked, self.counts, self.slots, self.lanes, self.rows, detected,
            np.ascontiguousarray(sensed.lane), out, lane, slot,
        )  # fmt: skip
        fields: dict[str, Any] = dict(zip(names, out, strict=True))
        count = np.where(self.tracked, 1 + self.counts, sensed.count)
        batch = dataclasses.replace(sensed, count=count, lane=lane, **fields)
        return TrackedBatch(batch, slot)
