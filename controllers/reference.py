"""Lateral references in the lane frame: quintic (minimum-jerk) lane changes, and lane keeping."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable

PEAK_SAMPLES = 64
"""Points a profile's peak lateral speed is sampled on (evenly over its duration, end excluded)."""


@register_jitable
def quintic_coefficients(
    d0: float, d1: float, duration: float, v0: float, a0: float
) -> tuple[float, float, float, float, float, float]:
    """c0..c5 [m/s^k] of the quintic from (d0 [m], v0 [m/s], a0 [m/s^2]) to (d1, 0, 0) over
    `duration` [s], in closed form: sums, products and quotients only, so the per-world profile and
    the batched kernels (which compile this very function) get the same bits."""
    t = duration
    t2 = t * t
    t3 = t2 * t
    h = d1 - d0
    c3 = (20.0 * h - 12.0 * v0 * t - 3.0 * a0 * t2) / (2.0 * t3)
    c4 = (-30.0 * h + 16.0 * v0 * t + 3.0 * a0 * t2) / (2.0 * t3 * t)
    c5 = (12.0 * h - 6.0 * v0 * t - a0 * t2) / (2.0 * t3 * t2)
    return d0, v0, a0 / 2.0, c3, c4, c5


@register_jitable
def quintic_at(
    c0: float, c1: float, c2: float, c3: float, c4: float, c5: float, tau: float
) -> tuple[float, float, float]:
    """(d [m], d_dot [m/s], d_ddot [m/s^2]) of the quintic c0..c5 at `tau` [s] by Horner's rule
    (no dot product: BLAS's summation order is not a compiled loop's)."""
    d = c0 + tau * (c1 + tau * (c2 + tau * (c3 + tau * (c4 + tau * c5))))
    d_dot = c1 + tau * (2.0 * c2 + tau * (3.0 * c3 + tau * (4.0 * c4 + tau * (5.0 * c5))))
    d_ddot = 2.0 * c2 + tau * (6.0 * c3 + tau * (12.0 * c4 + tau * (20.0 * c5)))
    return d, d_dot, d_ddot


@register_jitable
def quintic_peak_speed(
    c0: float, c1: float, c2: float, c3: float, c4: float, c5: float, duration: float
) -> float:
    """Largest |d_dot| [m/s] of the quintic c0..c5 over `PEAK_SAMPLES` points of [0, duration) [s]
    (`quintic_at`'s d_dot, written out: the sum's order is the per-world code's)."""
    step = duration / PEAK_SAMPLES
    peak = 0.0
    for k in range(PEAK_SAMPLES):
        tau = k * step
        d_dot = c1 + tau * (2.0 * c2 + tau * (3.0 * c3 + tau * (4.0 * c4 + tau * (5.0 * c5))))
        peak = max(peak, abs(d_dot))
    return peak


@register_jitable
def quintic_sample(
    c0: float,
    c1: float,
    c2: float,
    c3: float,
    c4: float,
    c5: float,
    t0: float,
    duration: float,
    d1: float,
    t: float,
) -> tuple[float, float, float]:
    """(d [m], d_dot [m/s], d_ddot [m/s^2]) at absolute time `t` [s] of the quintic c0..c5 that
    starts at `t0` and ends at `d1` after `duration` [s], constant afterwards."""
    tau = t - t0
    if tau >= duration:
        return d1, 0.0, 0.0
    return quintic_at(c0, c1, c2, c3, c4, c5, tau if tau > 0.0 else 0.0)


class WarpClock(NamedTuple):
    """A profile's own clock: profile time = `profile_anchor` + (t - `anchor`) x `rate` [s]."""

    anchor: float
    profile_anchor: float
    rate: float


@register_jitable
def warped_time(clock: WarpClock, t: float) -> float:
    """The profile time [s] of the `clock` at time `t` [s]."""
    return clock.profile_anchor + (t - clock.anchor) * clock.rate


@register_jitable
def warped_sample(
    c0: float,
    c1: float,
    c2: float,
    c3: float,
    c4: float,
    c5: float,
    t0: float,
    duration: float,
    d1: float,
    clock: WarpClock,
    t: float,
) -> tuple[float, float, float]:
    """`quintic_sample` on the `clock`'s profile time: d_dot scaled by its rate, d_ddot by the
    rate squared (`WarpedProfile`)."""
    d, d_dot, d_ddot = quintic_sample(c0, c1, c2, c3, c4, c5, t0, duration, d1, warped_time(clock, t))
    return d, d_dot * clock.rate, d_ddot * (clock.rate * clock.rate)


@register_jitable
def rewarped(clock: WarpClock, t: float, rate: float) -> WarpClock:
    """The `clock` from time `t` [s] on at `rate` (the same clock when the rate is unchanged)."""
    if rate == clock.rate:
        return clock
    return WarpClock(t, warped_time(clock, t), rate)


@register_jitable
def clock_rate(speed: float, tan_max_course: float, peak_lateral_speed: float) -> float:
    """How fast a profile whose peak lateral speed is `peak_lateral_speed` [m/s] may run at `speed`
    [m/s] so that its course stays within atan(`tan_max_course`): at most 1."""
    if peak_lateral_speed == 0.0:
        return 1.0
    return min(1.0, max(speed, 0.0) * tan_max_course / peak_lateral_speed)


@register_jitable
def road_to_reach(
    c0: float,
    c1: float,
    c2: float,
    c3: float,
    c4: float,
    c5: float,
    t0: float,
    duration: float,
    d1: float,
    profile_time: float,
    beyond: float,
    towards: float,
    speed: float,
    tan_max_course: float,
    peak_lateral_speed: float,
) -> float:
    """Road [m] the ego covers from profile time `profile_time` [s] until the quintic c0..c5 (from
    `t0`, over `duration` [s], ending at `d1` [m]) is past `beyond` [m] in the direction `towards`
    (+-1); inf when it never gets there. The profile is stepped in `PEAK_SAMPLES`ths of its duration
    (the first step past counts whole), and a profile second is max(`speed`, peak lateral speed /
    tan(max course)) metres of road: the profile's clock slows with the car (`clock_rate`), so at a
    crawl the road to a lateral position is the course's geometry, whatever the speed."""
    step = duration / PEAK_SAMPLES
    tau = max(profile_time, t0)
    while towards * (quintic_sample(c0, c1, c2, c3, c4, c5, t0, duration, d1, tau)[0] - beyond) < 0.0:
        if tau >= t0 + duration:
            return math.inf
        tau += step
    per_profile_second = max(speed, peak_lateral_speed / tan_max_course if tan_max_course > 0 else math.inf)
    return (tau - max(profile_time, t0)) * per_profile_second


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
        """c0..c5 of d(tau) = sum c_k tau^k, tau = t - t0 [s] (`quintic_coefficients`)."""
        return np.array(quintic_coefficients(self.d0, self.d1, self.duration, self.v0, self.a0))

    def sample(self, t: float) -> tuple[float, float, float]:
        """(d, d_dot, d_ddot) at absolute time t [s]."""
        c0, c1, c2, c3, c4, c5 = self.coefficients.tolist()
        return quintic_sample(c0, c1, c2, c3, c4, c5, self.t0, self.duration, self.d1, t)

    def samples(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(d [m], d_dot [m/s]) at each of the absolute `times` [s]: `sample` for a whole preview
        at once (the MPC's 20 ticks), the same Horner sums elementwise."""
        c0, c1, c2, c3, c4, c5 = self.coefficients.tolist()
        tau = np.maximum(times - self.t0, 0.0)
        d = c0 + tau * (c1 + tau * (c2 + tau * (c3 + tau * (c4 + tau * c5))))
        d_dot = c1 + tau * (2.0 * c2 + tau * (3.0 * c3 + tau * (4.0 * c4 + tau * (5.0 * c5))))
        finished = times - self.t0 >= self.duration
        return np.where(finished, self.d1, d), np.where(finished, 0.0, d_dot)

    def finished(self, t: float) -> bool:
        return t - self.t0 >= self.duration

    @cached_property
    def peak_lateral_speed(self) -> float:
        """Largest |d_dot| [m/s] over the profile (`quintic_peak_speed`: 64 points)."""
        c0, c1, c2, c3, c4, c5 = self.coefficients.tolist()
        return quintic_peak_speed(c0, c1, c2, c3, c4, c5, self.duration)


QUINTIC_PEAK_SPEED = 15.0 / 8.0
"""The minimum-jerk lane change's peak lateral speed is 15/8 * distance / duration."""


def drivable_duration(distance: float, speed: float, nominal: float, max_course: float) -> float:
    """The lane-change duration [s] for a lateral `distance` [m] at `speed` [m/s]: `nominal` [s],
    stretched so the quintic's peak lateral speed stays within speed * tan(max_course [rad])."""
    return stretched_duration(distance, speed, nominal, math.tan(max_course))


@register_jitable
def stretched_duration(distance: float, speed: float, nominal: float, tan_max_course: float) -> float:
    """`drivable_duration` with the course limit given as its tangent."""
    return max(nominal, QUINTIC_PEAK_SPEED * abs(distance) / (speed * tan_max_course))


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

    @property
    def clock(self) -> WarpClock:
        return WarpClock(self.anchor, self.profile_anchor, self.rate)

    def profile_time(self, t: float) -> float:
        return warped_time(self.clock, t)

    def sample(self, t: float) -> tuple[float, float, float]:
        profile = self.profile
        c0, c1, c2, c3, c4, c5 = profile.coefficients.tolist()
        return warped_sample(c0, c1, c2, c3, c4, c5, profile.t0, profile.duration, profile.d1, self.clock, t)

    def samples(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, d_dot = self.profile.samples(self.profile_anchor + (times - self.anchor) * self.rate)
        return d, d_dot * self.rate

    def finished(self, t: float) -> bool:
        return self.profile.finished(self.profile_time(t))

    def at_rate(self, t: float, rate: float) -> WarpedProfile:
        """This profile from time `t` [s] on at `rate` (itself when the rate is unchanged)."""
        clock = rewarped(self.clock, t, rate)
        return self if clock == self.clock else WarpedProfile(self.profile, *clock)


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
