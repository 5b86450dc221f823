"""Driver populations as data: the ranges (or log-normals) each population draws its drivers' IDM
and MOBIL parameters (and the distracted drivers' delay and sudden brakings) from, the habits of
its drivers (blind to the ego, yielding to it), the shares of `mixed`, and the check of a
population spec (a name, `random`, or shares of names); drawing and setting them is
`stack.sim.drivers`.
docs/traffic.md names the sources and the rates."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

HIGHWAY_ENV = "highway-env"
"""The default population: highway-env's one parameter set for every driver."""


@dataclass(frozen=True)
class LogNormal:
    """A parameter drawn log-normally per driver: `median`, and `log_std` the standard deviation of
    its natural logarithm, truncated to [`low`, `high`] (both > 0), in the parameter's own unit.
    Drawn by the inverse CDF of one uniform draw, so it consumes the generator as a uniform range
    does (`stack.sim.drivers.draw_driver`)."""

    median: float
    log_std: float
    low: float
    high: float

    def __post_init__(self) -> None:
        if not 0 < self.low <= self.median <= self.high or self.log_std <= 0:
            raise ValueError(f"a log-normal needs 0 < low <= median <= high and log_std > 0, got {self}")


Spread = tuple[float, float] | LogNormal
"""How a parameter is drawn: a uniform range (low, high), or a truncated `LogNormal`."""


def limits(spread: Spread) -> tuple[float, float]:
    """The lowest and highest value `spread` draws."""
    return (spread.low, spread.high) if isinstance(spread, LogNormal) else spread


@dataclass(frozen=True)
class DriverRanges:
    """What a population draws each driver's parameters from: a uniform range [low, high], or (the
    `calibrated` drivers' IDM parameters) a truncated `LogNormal`.

    desired_speed_factor: multiplies the driver's desired (IDM target) speed as the scenario drew it;
    time_gap_s: IDM's time gap T [s]; max_acceleration: IDM's a [m/s^2]; comfortable_deceleration:
    IDM's b [m/s^2]; jam_clearance_m: IDM's s0 [m], bumper to bumper (highway-env's jam distance is
    centre to centre: s0 + the vehicle's length); politeness: MOBIL's p; threshold: MOBIL's
    incentive threshold [m/s^2]; safe_braking: the most braking [m/s^2] a lane change may impose on
    the new follower (MOBIL's b_safe); decision_period_s: how often MOBIL is evaluated [s]."""

    desired_speed_factor: Spread
    time_gap_s: Spread
    max_acceleration: Spread
    comfortable_deceleration: Spread
    jam_clearance_m: Spread
    politeness: Spread
    threshold: Spread
    safe_braking: Spread
    decision_period_s: Spread
    perception_delay_s: tuple[float, float] | None = None
    sudden_braking_per_minute: tuple[float, float] | None = None
    sudden_braking_mps2: tuple[float, float] | None = None
    sudden_braking_s: tuple[float, float] | None = None
    blind_to_ego: bool = False
    yields_to_ego: bool = False
    """A distracted driver's habits, drawn after the parameters above when given:
    perception_delay_s, how old [s] the view of its leader is that its IDM acts on;
    sudden_braking_per_minute, the Poisson rate [1/min] of its brakings without cause, each
    sudden_braking_mps2 [m/s^2] strong (drawn once per driver) for sudden_braking_s [s]. The
    habits no driver draws: blind_to_ego, MOBIL's safety criterion does not see the ego as the new
    follower (it cuts in on it; IDM still follows it in its lane); yields_to_ego, a driver in the
    lane the ego is changing into, behind the ego, eases off to make room for it."""


DRIVER_PARAMETERS = tuple(field.name for field in fields(DriverRanges))[:9]
"""The parameters every drawn population draws, in the order they are drawn."""
HABIT_PARAMETERS = (
    "perception_delay_s",
    "sudden_braking_per_minute",
    "sudden_braking_mps2",
    "sudden_braking_s",
)
"""The parameters a population with habits draws after `DRIVER_PARAMETERS`, in that order."""


def _spread(value: Any) -> Any:
    """A YAML value as drawn: a flag as it is, a mapping as a `LogNormal`, a pair as a range."""
    if isinstance(value, bool):
        return value
    if isinstance(value, dict):
        return LogNormal(**{key: float(number) for key, number in value.items()})
    return (float(value[0]), float(value[1]))


def _ranges(data: dict[str, Any]) -> DriverRanges:
    """A population's `DriverRanges` from its YAML mapping."""
    return DriverRanges(**{key: _spread(value) for key, value in data.items()})


POPULATION_RANGES: dict[str, DriverRanges] = {
    name: _ranges(ranges)
    for name, ranges in yaml.safe_load((Path(__file__).parent / "drivers.yaml").read_text()).items()
}
"""Each drawn population's ranges (module docstring; docs/traffic.md)."""

MIXED_SHARES: dict[str, float] = {
    HIGHWAY_ENV: 0.2,
    "calibrated": 0.25,
    "aggressive": 0.15,
    "cautious": 0.15,
    "distracted": 0.15,
    "blind": 0.1,
}
"""`mixed`: the share of each population among the drivers."""

RANDOM = "random"
"""The population that draws one of `RANDOM_CHOICES` per episode (evenly) from the env's generator."""

POPULATIONS = (HIGHWAY_ENV, *POPULATION_RANGES, "mixed", RANDOM)
"""Every population by name."""

RANDOM_CHOICES = tuple(name for name in POPULATIONS if name != RANDOM)
"""What `random` draws from."""

STOCK_POPULATIONS = (HIGHWAY_ENV, "calibrated", "aggressive")
"""The populations stock highway-env's per-vehicle Python drives (the `stock` and `fast` backends):
parameters only, no habits."""


def check_population(drivers: str | Mapping[str, float]) -> None:
    """ValueError naming what is wrong unless `drivers` is a population, `random`, or shares."""
    if drivers != RANDOM:
        population_shares(drivers)


def stock_drives(drivers: str | Mapping[str, float] | None) -> bool:
    """Whether stock highway-env's Python drives `drivers` as the `vector` road does (no habits)."""
    if drivers is None:
        return True
    return drivers != RANDOM and set(population_shares(drivers)) <= set(STOCK_POPULATIONS)


def population_shares(drivers: str | Mapping[str, float]) -> dict[str, float]:
    """A population spec (a name, or shares of names) as shares of the elementary populations
    (`highway-env` and those of `POPULATION_RANGES`), summing to 1; ValueError names what is wrong."""
    if isinstance(drivers, str):
        if drivers not in POPULATIONS:
            raise ValueError(f"unknown driver population {drivers!r}; available: {', '.join(POPULATIONS)}")
        if drivers == RANDOM:
            raise ValueError("random draws one population per episode: it is not a share of one")
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
