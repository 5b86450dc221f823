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
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

HIGHWAY_ENV = "highway-env"
"""The default population: highway-env's one parameter set for every driver."""


@dataclass(frozen=True)
class DriverRanges:
    """The uniform ranges [low, high] a population draws each driver's parameters from.

    desired_speed_factor: multiplies the driver's desired (IDM target) speed as the scenario drew it;
    time_gap_s: IDM's time gap T [s]; max_acceleration: IDM's a [m/s^2]; comfortable_deceleration:
    IDM's b [m/s^2]; jam_clearance_m: IDM's s0 [m], bumper to bumper (highway-env's jam distance is
    centre to centre: s0 + the vehicle's length); politeness: MOBIL's p; threshold: MOBIL's
    incentive threshold [m/s^2]; safe_braking: the most braking [m/s^2] a lane change may impose on
    the new follower (MOBIL's b_safe); decision_period_s: how often MOBIL is evaluated [s]."""

    desired_speed_factor: tuple[float, float]
    time_gap_s: tuple[float, float]
    max_acceleration: tuple[float, float]
    comfortable_deceleration: tuple[float, float]
    jam_clearance_m: tuple[float, float]
    politeness: tuple[float, float]
    threshold: tuple[float, float]
    safe_braking: tuple[float, float]
    decision_period_s: tuple[float, float]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The lows and highs, in `DRIVER_PARAMETERS` order."""
        pairs = [getattr(self, name) for name in DRIVER_PARAMETERS]
        return np.array([low for low, _ in pairs]), np.array([high for _, high in pairs])


DRIVER_PARAMETERS = tuple(field.name for field in fields(DriverRanges))
"""The drawn parameters, in the order they are drawn."""

POPULATION_RANGES: dict[str, DriverRanges] = {
    "calibrated": DriverRanges(
        desired_speed_factor=(0.9, 1.1),
        time_gap_s=(0.8, 1.6),
        max_acceleration=(0.8, 1.6),
        comfortable_deceleration=(1.2, 2.5),
        jam_clearance_m=(1.5, 3.0),
        politeness=(0.0, 0.5),
        threshold=(0.1, 0.1),
        safe_braking=(4.0, 4.0),
        decision_period_s=(1.0, 1.0),
    ),
    "aggressive": DriverRanges(
        desired_speed_factor=(1.05, 1.2),
        time_gap_s=(0.6, 1.0),
        max_acceleration=(2.0, 3.0),
        comfortable_deceleration=(3.0, 5.0),
        jam_clearance_m=(1.0, 2.0),
        politeness=(0.0, 0.0),
        threshold=(0.0, 0.05),
        safe_braking=(4.0, 4.0),
        decision_period_s=(0.5, 0.5),
    ),
    "cautious": DriverRanges(
        desired_speed_factor=(0.85, 0.95),
        time_gap_s=(1.8, 2.5),
        max_acceleration=(0.8, 1.2),
        comfortable_deceleration=(1.0, 1.5),
        jam_clearance_m=(3.0, 5.0),
        politeness=(0.5, 1.0),
        threshold=(0.3, 0.3),
        safe_braking=(1.0, 1.0),
        decision_period_s=(2.0, 2.0),
    ),
}
"""Each drawn population's ranges (module docstring; docs/traffic.md)."""

MIXED_SHARES: dict[str, float] = {
    HIGHWAY_ENV: 0.25,
    "calibrated": 0.35,
    "aggressive": 0.2,
    "cautious": 0.2,
}
"""`mixed`: the share of each population among the drivers."""

POPULATIONS = (HIGHWAY_ENV, *POPULATION_RANGES, "mixed")
"""Every population by name."""


def population_shares(drivers: str | Mapping[str, float]) -> dict[str, float]:
    """A population spec (a name, or shares of names) as shares of the elementary populations
    (`highway-env` and those of `POPULATION_RANGES`), summing to 1; ValueError names what is wrong."""
    if isinstance(drivers, str):
        if drivers not in POPULATIONS:
            raise ValueError(f"unknown driver population {drivers!r}; available: {', '.join(POPULATIONS)}")
        return dict(MIXED_SHARES) if drivers == "mixed" else {drivers: 1.0}
    shares: dict[str, float] = {}
    for name, share in drivers.items():
        if not isinstance(share, int | float) or isinstance(share, bool) or not 0 < share <= 1:
            raise ValueError(f"the share of {name!r} must be a number in (0, 1], got {share!r}")
        for part, part_share in population_shares(str(name)).items():
            shares[part] = shares.get(part, 0.0) + float(share) * part_share
    total = sum(float(share) for share in drivers.values())
    if not shares or abs(total - 1.0) > 1e-6:
        raise ValueError(f"the populations' shares must sum to 1, got {total:g}")
    return shares


def draws_nothing(drivers: str | Mapping[str, float] | None) -> bool:
    """Whether `drivers` leaves every driver highway-env's (nothing drawn)."""
    return drivers is None or population_shares(drivers) == {HIGHWAY_ENV: 1.0}


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
    low, high = POPULATION_RANGES[population].bounds()
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
