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
from statistics import NormalDist
from typing import Any

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


def uniform_bounds(ranges: DriverRanges) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of the one uniform draw per parameter of `ranges`, in `DRIVER_PARAMETERS` order:
    a range's low and high, a `LogNormal`'s truncation as quantiles of the standard normal."""
    lows, highs = [], []
    for name in DRIVER_PARAMETERS:
        spread = getattr(ranges, name)
        if isinstance(spread, LogNormal):
            lows.append(STANDARD_NORMAL.cdf(np.log(spread.low / spread.median) / spread.log_std))
            highs.append(STANDARD_NORMAL.cdf(np.log(spread.high / spread.median) / spread.log_std))
        else:
            lows.append(spread[0])
            highs.append(spread[1])
    return np.array(lows), np.array(highs)


def from_uniform(ranges: DriverRanges, uniform: np.ndarray) -> list[float]:
    """The parameters of `ranges` for one uniform draw each (`uniform_bounds`): a range's as drawn, a
    `LogNormal`'s by its inverse CDF, clipped to its truncation."""
    values = uniform.tolist()
    for index, name in enumerate(DRIVER_PARAMETERS):
        spread = getattr(ranges, name)
        if isinstance(spread, LogNormal):
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
    ranges = POPULATION_RANGES[population]
    low, high = uniform_bounds(ranges)
    values = dict(zip(DRIVER_PARAMETERS, from_uniform(ranges, rng.uniform(low, high)), strict=True))
    if ranges.perception_delay_s is None:
        return DrawnDriver(population, values)
    habit_ranges = [getattr(ranges, name) for name in HABIT_PARAMETERS]
    habits = rng.uniform([low for low, _ in habit_ranges], [high for _, high in habit_ranges])
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
