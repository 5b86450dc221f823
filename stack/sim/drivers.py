"""Driver populations: the IDM and MOBIL parameters each traffic vehicle's driver draws at spawn.

highway-env gives every IDM vehicle one parameter set (class constants of `IDMVehicle`). A population
other than `highway-env` gives each traffic driver its own, drawn from the env's seeded generator
once the road is filled (`assign_drivers`), and set as instance attributes of the very names
highway-env's `IDMVehicle` reads (`TIME_WANTED`, `COMFORT_ACC_MAX`, ...): stock's per-vehicle
`act`, the `vector` road's arrays and the batch's columns all read the driver's own values, so the
three drive the same traffic. The `highway-env` population draws nothing and sets nothing: the
spawn, the generator's stream and every trajectory stay highway-v0's.

`calibrated` is built around the highway parameter set of Treiber and Kesting's calibrations of IDM
and MOBIL (docs/traffic.md names the sources and the mapping); `aggressive`, `cautious` and the
shares of `mixed` are this project's. Every range is drawn uniformly, one driver after another in
road order, parameters in `DRIVER_PARAMETERS` order."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from stack.settings.drivers import (
    DRIVER_PARAMETERS,
    HIGHWAY_ENV,
    POPULATION_RANGES,
    DriverRanges,
    population_shares,
)


def draws_nothing(drivers: str | Mapping[str, float] | None) -> bool:
    """Whether `drivers` leaves every driver highway-env's (nothing drawn)."""
    return drivers is None or population_shares(drivers) == {HIGHWAY_ENV: 1.0}


def bounds(ranges: DriverRanges) -> tuple[np.ndarray, np.ndarray]:
    """The lows and highs of `ranges`, in `DRIVER_PARAMETERS` order."""
    pairs = [getattr(ranges, name) for name in DRIVER_PARAMETERS]
    return np.array([low for low, _ in pairs]), np.array([high for _, high in pairs])


@dataclass(frozen=True)
class DrawnDriver:
    """One driver's parameters (`DriverRanges` fields, one value each) and its population."""

    population: str
    values: dict[str, float]


def draw_driver(rng: np.random.Generator, names: list[str], odds: np.ndarray) -> DrawnDriver:
    """One driver: its population drawn by `odds` among `names` (no draw for a single one), then,
    unless it is `highway-env`'s, its parameters (one uniform draw per parameter, in order)."""
    population = names[int(rng.choice(len(names), p=odds))] if len(names) > 1 else names[0]
    if population == HIGHWAY_ENV:
        return DrawnDriver(population, {})
    low, high = bounds(POPULATION_RANGES[population])
    values = rng.uniform(low, high)
    return DrawnDriver(population, dict(zip(DRIVER_PARAMETERS, values.tolist(), strict=True)))


def apply_driver(vehicle: Any, driver: DrawnDriver) -> None:
    """Set `driver`'s parameters on an IDM `vehicle` under the names highway-env's `IDMVehicle`
    reads (its desired speed scaled, its jam distance centre to centre)."""
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


def assign_drivers(
    vehicles: list[Any],
    drivers: str | Mapping[str, float] | None,
    rng: np.random.Generator,
    kinds: tuple[type, ...],
) -> None:
    """Draw a driver (`draw_driver`) for every vehicle of `kinds` (IDM drivers) in `vehicles`, in
    road order, from `rng`, and set it (`apply_driver`); nothing at all for `highway-env`'s."""
    if draws_nothing(drivers):
        return
    assert drivers is not None
    shares = population_shares(drivers)
    names = list(shares)
    odds = np.array([shares[name] for name in names])
    odds = odds / odds.sum()
    for vehicle in vehicles:
        if type(vehicle) in kinds:
            apply_driver(vehicle, draw_driver(rng, names, odds))
