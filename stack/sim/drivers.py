"""Driver populations: the IDM and MOBIL parameters each traffic vehicle's driver draws at spawn.

highway-env gives every IDM vehicle one parameter set (class constants of `IDMVehicle`). A population
other than `highway-env` gives each traffic driver its own, drawn from the env's seeded generator
once the road is filled (`assign_drivers`), and set as instance attributes of the very names
highway-env's `IDMVehicle` reads (`TIME_WANTED`, `COMFORT_ACC_MAX`, ...): stock's per-vehicle
`act`, the `vector` road's arrays and the batch's columns all read the driver's own values, so the
three drive the same traffic. The `highway-env` population draws nothing and sets nothing: the
spawn, the generator's stream and every trajectory stay highway-v0's.

`calibrated` draws its IDM parameters log-normally around the population medians of Zhang and
Sun's hierarchical calibration of IDM to highD, its MOBIL parameters as Kesting, Treiber and Helbing
give them (docs/traffic.md names the sources and the mapping); `aggressive`, `cautious` and the
shares of `mixed` are this project's. Each parameter is one uniform draw (through a `LogNormal`'s
inverse CDF where the population gives one), one driver after another in road order, parameters in
`DRIVER_PARAMETERS` order, then a distracted driver's `HABIT_PARAMETERS`
and the key of its sudden brakings. A driver's habits (`DriverHabits`: its perception delay, its
sudden brakings, blind to the ego, yielding to it) are set as its `habits`; stock highway-env
knows none of them (`stack.worlds.drivers.STOCK_POPULATIONS`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from statistics import NormalDist
from typing import Any, NamedTuple

import numpy as np

from stack.worlds.drivers import (
    DRIVER_PARAMETERS,
    HABIT_PARAMETERS,
    HIGHWAY_ENV,
    POPULATION_RANGES,
    RANDOM,
    RANDOM_CHOICES,
    DriverRanges,
    LogNormal,
    population_shares,
)

SEEN_FRAMES = 32
"""Frames of every vehicle's past (s and speed) a road keeps for its distracted drivers: the
longest perception delay is one frame fewer (1.5 s needs 23 at 15 Hz)."""
KEY_LIMIT = 2**62
"""Sudden-braking keys are drawn in [0, KEY_LIMIT)."""


@dataclass(frozen=True)
class DriverHabits:
    """What a driver does beyond IDM and MOBIL, per frame of the road: `delay_frames`, how many
    frames old the view of its leader is that IDM reads (gap and closing speed); its sudden
    brakings without cause, an onset each frame with `sudden_braking_chance` (a Poisson rate),
    `sudden_braking_mps2` [m/s^2] for `sudden_braking_frames` frames, decided by a counter-based
    hash of its `key` (drawn at spawn) and the frame (`stack.sim.vector.habits`); `blind_to_ego`,
    MOBIL does not see the ego as its new follower; `yields_to_ego`, it eases off for the ego's
    lane change into its lane."""

    delay_frames: int = 0
    sudden_braking_chance: float = 0.0
    sudden_braking_frames: int = 0
    sudden_braking_mps2: float = 0.0
    key: int = 0
    blind_to_ego: bool = False
    yields_to_ego: bool = False


NO_HABITS = DriverHabits()
"""highway-env's drivers: IDM and MOBIL only."""


def habits_of(vehicle: Any) -> DriverHabits:
    """A driver's habits (`NO_HABITS` unless its population gave it some)."""
    return getattr(vehicle, "habits", NO_HABITS)


def draws_nothing(drivers: str | Mapping[str, float] | None) -> bool:
    """Whether `drivers` leaves every driver highway-env's (nothing drawn)."""
    return drivers is None or (drivers != RANDOM and population_shares(drivers) == {HIGHWAY_ENV: 1.0})


STANDARD_NORMAL = NormalDist()


class DrawPlan(NamedTuple):
    """How one population's drivers are drawn, worked out once (`draw_plan`): the bounds of the one
    uniform draw per parameter in `DRIVER_PARAMETERS` order (`low`, and `span` = high - low; a
    `LogNormal`'s truncation as quantiles of the standard normal), the `LogNormal`s by index, and
    the habits' (low, span) likewise (None: a population without habits)."""

    low: np.ndarray
    span: np.ndarray
    log_normals: tuple[tuple[int, LogNormal], ...]
    habit_bounds: tuple[np.ndarray, np.ndarray] | None


@cache
def draw_plan(ranges: DriverRanges) -> DrawPlan:
    """`ranges`' `DrawPlan`."""
    lows, highs, log_normals = [], [], []
    for index, name in enumerate(DRIVER_PARAMETERS):
        spread = getattr(ranges, name)
        if isinstance(spread, LogNormal):
            lows.append(STANDARD_NORMAL.cdf(np.log(spread.low / spread.median) / spread.log_std))
            highs.append(STANDARD_NORMAL.cdf(np.log(spread.high / spread.median) / spread.log_std))
            log_normals.append((index, spread))
        else:
            lows.append(spread[0])
            highs.append(spread[1])
    low = np.array(lows)
    habit_bounds = None
    if ranges.perception_delay_s is not None:
        habit_ranges = np.array([getattr(ranges, name) for name in HABIT_PARAMETERS], dtype=float)
        habit_bounds = (habit_ranges[:, 0], habit_ranges[:, 1] - habit_ranges[:, 0])
    return DrawPlan(low, np.array(highs) - low, tuple(log_normals), habit_bounds)


def uniform(rng: np.random.Generator, low: np.ndarray, span: np.ndarray) -> np.ndarray:
    """`rng.uniform(low, low + span)`, bit for bit and drawing the same doubles (numpy's uniform is
    low + (high - low) x one double each), without the cost of its broadcasting (~10 us a call)."""
    return low + span * rng.random(len(low))


def from_uniform(plan: DrawPlan, uniform_draws: np.ndarray) -> list[float]:
    """The parameters of `plan` for one uniform draw each: a range's as drawn, a `LogNormal`'s by its
    inverse CDF, clipped to its truncation."""
    values = uniform_draws.tolist()
    for index, spread in plan.log_normals:
        drawn = spread.median * np.exp(spread.log_std * STANDARD_NORMAL.inv_cdf(values[index]))
        values[index] = float(min(max(drawn, spread.low), spread.high))
    return values


@dataclass(frozen=True)
class DrawnDriver:
    """One driver's parameters (`DriverRanges` fields, one value each) and its population."""

    population: str
    values: dict[str, float]
    key: int = 0


def draw_driver(rng: np.random.Generator, names: list[str], odds: np.ndarray) -> DrawnDriver:
    """One driver: its population drawn by `odds` among `names` (no draw for a single one), then,
    unless it is `highway-env`'s, its parameters (one uniform draw per parameter, in order, mapped
    through a `LogNormal`'s inverse CDF where the population gives one), then
    its habits' parameters and its key (a population with habits to draw)."""
    population = names[int(rng.choice(len(names), p=odds))] if len(names) > 1 else names[0]
    if population == HIGHWAY_ENV:
        return DrawnDriver(population, {})
    plan = draw_plan(POPULATION_RANGES[population])
    values = dict(zip(DRIVER_PARAMETERS, from_uniform(plan, uniform(rng, plan.low, plan.span)), strict=True))
    if plan.habit_bounds is None:
        return DrawnDriver(population, values)
    habits = uniform(rng, *plan.habit_bounds)
    values |= dict(zip(HABIT_PARAMETERS, habits.tolist(), strict=True))
    return DrawnDriver(population, values, int(rng.integers(0, KEY_LIMIT)))


def habits(driver: DrawnDriver, frequency: float) -> DriverHabits:
    """`driver`'s habits on a road of `frequency` frames a second [Hz]; ValueError for a delay
    longer than the road keeps (`SEEN_FRAMES`)."""
    ranges = POPULATION_RANGES[driver.population]
    value = driver.values
    if "perception_delay_s" not in value:
        return DriverHabits(blind_to_ego=ranges.blind_to_ego, yields_to_ego=ranges.yields_to_ego)
    delay_frames = round(value["perception_delay_s"] * frequency)
    if delay_frames >= SEEN_FRAMES:
        raise ValueError(
            f"a perception delay of {value['perception_delay_s']:g} s is {delay_frames} frames at "
            f"{frequency:g} Hz; at most {SEEN_FRAMES - 1}"
        )
    return DriverHabits(
        delay_frames=delay_frames,
        sudden_braking_chance=float(-np.expm1(-value["sudden_braking_per_minute"] / 60 / frequency)),
        sudden_braking_frames=max(1, round(value["sudden_braking_s"] * frequency)),
        sudden_braking_mps2=value["sudden_braking_mps2"],
        key=driver.key,
        blind_to_ego=ranges.blind_to_ego,
        yields_to_ego=ranges.yields_to_ego,
    )


def apply_driver(vehicle: Any, driver: DrawnDriver, frequency: float) -> None:
    """Set `driver`'s parameters on an IDM `vehicle` under the names highway-env's `IDMVehicle`
    reads (its desired speed scaled, its jam distance centre to centre), and its habits on a road
    of `frequency` frames a second [Hz] as its `habits` (none: nothing set)."""
    if not driver.values:
        return
    value = driver.values
    vehicle.target_speed = float(vehicle.target_speed) * value["desired_speed_factor"]
    vehicle.TIME_WANTED = value["time_gap_s"]
    vehicle.COMFORT_ACC_MAX = value["max_acceleration"]
    vehicle.COMFORT_ACC_MIN = -value["comfortable_deceleration"]
    vehicle.DISTANCE_WANTED = value["jam_clearance_m"] + float(vehicle.LENGTH)
    vehicle.POLITENESS = value["politeness"]
    vehicle.LANE_CHANGE_MIN_ACC_GAIN = value["threshold"]
    vehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED = value["safe_braking"]
    vehicle.LANE_CHANGE_DELAY = value["decision_period_s"]
    drawn_habits = habits(driver, frequency)
    if drawn_habits != NO_HABITS:
        vehicle.habits = drawn_habits


def assign_drivers(
    vehicles: list[Any],
    drivers: str | Mapping[str, float] | None,
    rng: np.random.Generator,
    kinds: tuple[type, ...],
    frequency: float,
) -> str:
    """Draw a driver (`draw_driver`) for every vehicle of `kinds` (IDM drivers) in `vehicles`, in
    road order, from `rng`, and set it (`apply_driver`, on a road of `frequency` frames a second
    [Hz]); nothing at all for `highway-env`'s. `random` first draws one of `RANDOM_CHOICES`
    (evenly). The population driven (its name, or the shares' spec)."""
    if drivers == RANDOM:
        drivers = RANDOM_CHOICES[int(rng.integers(len(RANDOM_CHOICES)))]
    if draws_nothing(drivers):
        return HIGHWAY_ENV
    assert drivers is not None
    shares = population_shares(drivers)
    names = list(shares)
    odds = np.array([shares[name] for name in names])
    odds = odds / odds.sum()
    for vehicle in vehicles:
        if type(vehicle) in kinds:
            apply_driver(vehicle, draw_driver(rng, names, odds), frequency)
    return drivers if isinstance(drivers, str) else ",".join(f"{k}={v:g}" for k, v in drivers.items())
