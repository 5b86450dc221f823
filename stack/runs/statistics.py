"""95 % confidence intervals for the per-episode metrics `compare` reports.

Means (speed, lane changes, masked and aborted commands) get Student's t interval over episodes;
rates of 0/1 outcomes (collisions) get Wilson's score interval, which stays inside [0, 1] and is
not empty when no episode crashed. Two agents driven on the same seeds are compared by the paired
difference per episode (agent minus baseline) with its t interval: the traffic of each seed is
the same for both, so pairing removes most of the between-seed spread.

scipy.stats is imported by the intervals that need it: `drivestack run` imports this module with
`compare`'s tables and computes none (~0.7 CPU-s of its start-up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LEVEL = 0.95
"""Confidence level of every interval."""


@dataclass(frozen=True)
class Interval:
    """An estimate and its 95 % confidence interval, in the metric's units."""

    value: float
    low: float
    high: float

    def as_list(self) -> list[float]:
        return [self.value, self.low, self.high]


def mean_interval(values: np.ndarray | list[float], floor: float = -math.inf) -> Interval:
    """Mean and Student's t interval (a single value: the interval is that value), cut at `floor`
    for a metric that cannot go below it (a count cannot be negative)."""
    from scipy import stats

    data = np.asarray(values, dtype=float)
    mean = float(np.mean(data))
    if len(data) < 2:
        return Interval(mean, mean, mean)
    half = float(stats.t.ppf((1 + LEVEL) / 2, len(data) - 1) * np.std(data, ddof=1) / math.sqrt(len(data)))
    return Interval(mean, max(floor, mean - half), mean + half)


def rate_interval(successes: int, trials: int) -> Interval:
    """Rate and Wilson's score interval of `successes` out of `trials`."""
    from scipy import stats

    rate = successes / trials
    z = float(stats.norm.ppf((1 + LEVEL) / 2))
    centre = (rate + z**2 / (2 * trials)) / (1 + z**2 / trials)
    half = z / (1 + z**2 / trials) * math.sqrt(rate * (1 - rate) / trials + z**2 / (4 * trials**2))
    return Interval(rate, min(rate, max(0.0, centre - half)), max(rate, min(1.0, centre + half)))


def paired_difference(agent: list[float], baseline: list[float]) -> Interval:
    """Mean of agent - baseline over the same episodes, with its t interval."""
    if len(agent) != len(baseline):
        raise ValueError(f"paired difference needs the same episodes: {len(agent)} vs {len(baseline)}")
    return mean_interval(np.asarray(agent, dtype=float) - np.asarray(baseline, dtype=float))
