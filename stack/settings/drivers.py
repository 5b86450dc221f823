"""Driver populations as data: the ranges each population draws its drivers' IDM and MOBIL
parameters from, the shares of `mixed`, and the check of a population spec (a name, or shares of
names); drawing and setting them is `stack.sim.drivers`. docs/traffic.md names the sources."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path

import yaml

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


DRIVER_PARAMETERS = tuple(field.name for field in fields(DriverRanges))
"""The drawn parameters, in the order they are drawn."""

POPULATION_RANGES: dict[str, DriverRanges] = {
    name: DriverRanges(**{key: (float(low), float(high)) for key, (low, high) in ranges.items()})
    for name, ranges in yaml.safe_load((Path(__file__).parent / "drivers.yaml").read_text()).items()
}
"""Each drawn population's ranges (module docstring; docs/traffic.md)."""

MIXED_SHARES: dict[str, float] = {HIGHWAY_ENV: 0.25, "calibrated": 0.35, "aggressive": 0.2, "cautious": 0.2}
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
