"""How an episode's metrics are measured from what every recorder keeps of it (`EpisodeSamples`):
each field of the episode record that is measured from the samples declares its measurer
(`declared(..., measure=...)`, `stack.results.episode_fields`), and both paths, the per-world
`EpisodeRecorder` and the batch's `EpisodeMetricsBatch` (`stack.loop.metrics`), hand their samples
to `measured`, which runs every declared measurer. So a metric of the ego's own motion is its
field and its measurer, and nothing else names it.

The summary entries that combine fields of a run's episodes (accuracy, collisions not at fault,
failures) are here too.

- comfort: peak |lateral acceleration| (a_y = v * yaw rate relative to the reference lane, so a
  bend's own v^2 / R is not counted) and peak lateral jerk, both over a 500 ms moving average, as
  UN R79 measures them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import fields
from typing import Any, NamedTuple

import numpy as np

COMFORT_WINDOW_S = 0.5
"""Moving-average window for lateral acceleration and jerk [s] (UN R79)."""
STOPPED_SPEED_MPS = 0.5
"""Below this speed a vehicle counts as stopped [m/s]."""


class EpisodeSamples(NamedTuple):
    """What every recorder keeps of an episode, sampled at the start and after every control tick
    (one sample more than ticks), `dt` seconds [s] apart: the time [s], the ego's speed [m/s], its
    heading relative to its lane [rad], its lateral offset [m] and its lane, and the vehicles it
    passed (`passed_cars`, each counted once, the first time it went from ahead of the ego to
    behind it)."""

    time: np.ndarray
    speed: np.ndarray
    heading: np.ndarray
    d: np.ndarray
    lane: np.ndarray
    passed_cars: int
    dt: float


def measured(record: type, samples: EpisodeSamples) -> dict[str, Any]:
    """Every field of the dataclass `record` that declares a measurer, measured on `samples`, and
    the episode's `trace` (time [s], speed [m/s] and lateral offset [m] of every sample)."""
    trace = {"time": samples.time.tolist(), "speed": samples.speed.tolist(), "d": samples.d.tolist()}
    values: dict[str, Any] = {"trace": trace}
    for f in fields(record):
        how = f.metadata.get("reported")
        if how is not None and how.measure is not None:
            values[f.name] = how.measure(samples)
    return values


def moving_average(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing moving average over `window` samples (shorter at the start)."""
    if window <= 1 or len(values) == 0:
        return values
    sums = np.cumsum(np.insert(values, 0, 0.0))
    counts = np.minimum(np.arange(1, len(values) + 1), window)
    return (sums[1:] - sums[np.maximum(np.arange(1, len(values) + 1) - window, 0)]) / counts


def lateral_series(heading: np.ndarray, speed: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(a_y [m/s^2] from the second sample on, jerk [m/s^3] from the third), each a 500 ms moving
    average, from heading [rad] and speed [m/s] samples `dt` seconds apart."""
    window = max(1, round(COMFORT_WINDOW_S / dt))
    lateral_acceleration = moving_average(speed[1:] * np.diff(heading) / dt, window)
    return lateral_acceleration, moving_average(np.diff(lateral_acceleration) / dt, window)


def lateral_comfort(heading: np.ndarray, speed: np.ndarray, dt: float) -> tuple[float, float]:
    """(peak |a_y| [m/s^2], peak |jerk| [m/s^3]) from heading [rad] and speed [m/s] samples."""
    if len(heading) < 3:
        return 0.0, 0.0
    lateral_acceleration, jerk = lateral_series(heading, speed, dt)
    return float(np.max(np.abs(lateral_acceleration))), float(np.max(np.abs(jerk)))


def longest_run(flags: np.ndarray) -> int:
    """Length of the longest run of True in `flags` (0 if none)."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], flags.astype(np.int8), [0]))))
    return int((edges[1::2] - edges[::2]).max(initial=0))


def steps(samples: EpisodeSamples) -> int:
    """Control ticks."""
    return len(samples.time) - 1


def duration_s(samples: EpisodeSamples) -> float:
    """From the first sample to the last [s]."""
    return float(samples.time[-1] - samples.time[0])


def passed_cars(samples: EpisodeSamples) -> int:
    """Vehicles passed (`EpisodeSamples`)."""
    return samples.passed_cars


def mean_speed(samples: EpisodeSamples) -> float:
    """The ego's mean speed over the samples [m/s]."""
    return float(np.mean(samples.speed))


def peak_lat_accel(samples: EpisodeSamples) -> float:
    """Peak |lateral acceleration| [m/s^2] (module docstring)."""
    return lateral_comfort(samples.heading, samples.speed, samples.dt)[0]


def peak_lat_jerk(samples: EpisodeSamples) -> float:
    """Peak |lateral jerk| [m/s^3] (module docstring)."""
    return lateral_comfort(samples.heading, samples.speed, samples.dt)[1]


def longest_standstill_s(samples: EpisodeSamples) -> float:
    """The most ticks in a row that ended with the ego below `STOPPED_SPEED_MPS`, times the tick
    [s]: an ego that cannot get round a blocked lane stands still for the rest of the episode."""
    return longest_run(samples.speed[1:] < STOPPED_SPEED_MPS) * samples.dt


def time_in_leftmost_lane_s(samples: EpisodeSamples) -> float:
    """The ticks that ended with the ego in lane 0 (the lane keep-right rules reserve for
    overtaking), times the tick [s]."""
    return float(np.count_nonzero(samples.lane[1:] == 0) * samples.dt)


def not_at_fault(values: list[bool], episodes: Sequence[Any]) -> int:
    """Collisions not at fault: all collisions but those at fault (`values`)."""
    return sum(e.crashed for e in episodes) - sum(values)


def failures(values: list[bool], episodes: Sequence[Any]) -> int:
    """Episodes with an at-fault collision or a road departure."""
    return sum(e.at_fault_collision or e.road_departure for e in episodes)


def accuracy(values: list[int], episodes: Sequence[Any]) -> float | None:
    """The paper's accuracy [%]: passed / (passed + collided) x 100; None when both are 0."""
    passed, collisions = sum(values), sum(e.crashed for e in episodes)
    return 100.0 * passed / (passed + collisions) if passed + collisions else None
