"""Lateral references in the lane frame: quintic (minimum-jerk) lane changes, and lane keeping."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class QuinticProfile:
    """d(t) from (d0, v0, a0) at t0 to (d1, 0, 0) at t0 + duration; constant d1 afterwards.

    With v0 = a0 = 0 this is the minimum-jerk lane change d0 + (d1 - d0)(10u^3 - 15u^4 + 6u^5).
    Starting from the current lateral velocity and acceleration gives a smooth abort or re-target.
    Units: m, m/s, m/s^2, s.
    """

    d0: float
    d1: float
    t0: float
    duration: float
    v0: float = 0.0
    a0: float = 0.0

    @cached_property
    def coefficients(self) -> np.ndarray:
        T = self.duration
        c0, c1, c2 = self.d0, self.v0, self.a0 / 2.0
        A = np.array([[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4], [6 * T, 12 * T**2, 20 * T**3]])
        b = np.array([self.d1 - (c0 + c1 * T + c2 * T**2), -(c1 + 2 * c2 * T), -2 * c2])
        return np.concatenate([[c0, c1, c2], np.linalg.solve(A, b)])

    def sample(self, t: float) -> tuple[float, float, float]:
        """(d, d_dot, d_ddot) at absolute time t [s]."""
        if self.finished(t):
            return self.d1, 0.0, 0.0
        tau = max(t - self.t0, 0.0)
        c = self.coefficients
        powers = tau ** np.arange(6)
        d = float(c @ powers)
        d_dot = float(sum(k * c[k] * tau ** (k - 1) for k in range(1, 6)))
        d_ddot = float(sum(k * (k - 1) * c[k] * tau ** (k - 2) for k in range(2, 6)))
        return d, d_dot, d_ddot

    def samples(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(d [m], d_dot [m/s]) at each of the absolute `times` [s]: `sample` for a whole preview
        at once (the MPC's 20 ticks in 10 us instead of 120)."""
        c = self.coefficients
        tau = np.maximum(times - self.t0, 0.0)
        powers = tau[:, None] ** np.arange(6)
        d = powers @ c
        d_dot = powers[:, :5] @ (np.arange(1, 6) * c[1:])
        finished = times - self.t0 >= self.duration
        return np.where(finished, self.d1, d), np.where(finished, 0.0, d_dot)

    def finished(self, t: float) -> bool:
        return t - self.t0 >= self.duration

    @cached_property
    def peak_lateral_speed(self) -> float:
        """Largest |d_dot| [m/s] over the profile (sampled on 64 points)."""
        _, d_dot = self.samples(self.t0 + np.linspace(0.0, self.duration, 64, endpoint=False))
        return float(np.max(np.abs(d_dot)))


QUINTIC_PEAK_SPEED = 15.0 / 8.0
"""The minimum-jerk lane change's peak lateral speed is 15/8 * distance / duration."""


def drivable_duration(distance: float, speed: float, nominal: float, max_course: float) -> float:
    """The lane-change duration [s] for a lateral `distance` [m] at `speed` [m/s]: `nominal` [s],
    stretched so the quintic's peak lateral speed stays within speed * tan(max_course [rad])."""
    return max(nominal, QUINTIC_PEAK_SPEED * abs(distance) / (speed * math.tan(max_course)))


@dataclass(frozen=True)
class WarpedProfile:
    """A lateral profile run on its own clock: profile time = `profile_anchor` + (t - `anchor`) *
    `rate`, so at rate < 1 it is driven slower than planned (rate 0: held), and d_dot scales by
    `rate`, d_ddot by `rate`^2. The maneuver sets the rate from the ego's speed so the course the
    profile asks for never exceeds what that speed allows (`Maneuver.reference`)."""

    profile: QuinticProfile
    anchor: float = 0.0
    profile_anchor: float = 0.0
    rate: float = 1.0

    def profile_time(self, t: float) -> float:
        return self.profile_anchor + (t - self.anchor) * self.rate

    def sample(self, t: float) -> tuple[float, float, float]:
        d, d_dot, d_ddot = self.profile.sample(self.profile_time(t))
        return d, d_dot * self.rate, d_ddot * self.rate**2

    def samples(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, d_dot = self.profile.samples(self.profile_anchor + (times - self.anchor) * self.rate)
        return d, d_dot * self.rate

    def finished(self, t: float) -> bool:
        return self.profile.finished(self.profile_time(t))

    def at_rate(self, t: float, rate: float) -> WarpedProfile:
        """This profile from time `t` [s] on at `rate` (itself when the rate is unchanged)."""
        if rate == self.rate:
            return self
        return WarpedProfile(self.profile, t, self.profile_time(t), rate)


def lane_change(
    lane_offsets: Sequence[float] | np.ndarray,
    origin: int,
    target: int,
    d0: float,
    t0: float,
    duration: float,
    v0: float = 0.0,
) -> QuinticProfile:
    """The quintic from the current lateral state (d0 [m], v0 [m/s]) to the centre of `target`, an
    adjacent lane of the road whose lane centres are `lane_offsets` [m]."""
    if not 0 <= target < len(lane_offsets) or abs(target - origin) != 1:
        raise ValueError(
            f"target lane {target} is not reachable from lane {origin} "
            f"(road lanes 0..{len(lane_offsets) - 1}, one lane at a time)"
        )
    if not duration > 0:
        raise ValueError(f"lane-change duration must be > 0 s, got {duration}")
    return QuinticProfile(d0=d0, d1=float(lane_offsets[target]), t0=t0, duration=duration, v0=v0)


def lane_keeping(d_centre: float, t: float) -> QuinticProfile:
    """Hold the lane centre: the degenerate profile that is already at its end."""
    return QuinticProfile(d0=d_centre, d1=d_centre, t0=t, duration=1e-9)
