"""The ego's state and settings in a batch of closed loops, as named records the compiled steps
(`stack.batch.loop_kernels`) take: one row a world of what `Maneuver` and the controllers hold."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from common.longitudinal import BrakingLimits, GapKeeping
from controllers.lateral import LateralGains
from controllers.pid import PIDTerms


class ManeuverSettings(NamedTuple):
    """The maneuver's settings as `controllers.maneuver.Maneuver` holds them."""

    duration: float
    """Nominal lane-change duration [s]."""
    min_speed: float
    """Slowest speed a lane change starts at [m/s]."""
    tan_max_course: float
    """Tangent of the largest course a lane change asks for."""
    set_speed: float
    """The cruise's set speed [m/s]."""
    cut_in_lookahead_s: float
    """How far ahead a vehicle's sideways motion makes it a lane's leader [s] (`leaders_in_rows`)."""
    weaver_wary_s: float
    """How long a vehicle that turned back mid lane change is the cruise's leader [s]."""


class ManeuverArrays(NamedTuple):
    """Each world's maneuver (`Maneuver`'s state, one row a world): lane and target, the quintic's
    coefficients (W, 6), its profile [t0, duration, end, peak lateral speed] and clock [anchor,
    profile anchor, rate], and the counts [lane changes, masked, aborted]."""

    lane: np.ndarray
    target: np.ndarray
    coef: np.ndarray
    profile: np.ndarray
    clock: np.ndarray
    counts: np.ndarray


class ControllerArrays(NamedTuple):
    """Each world's controller state (one row a world): the lateral PID [integral, output, has
    output, last steering], the speed PI [integral, output, has output], emergency braking's
    per-vehicle memory (`seen`, `seen_speed`, `seen_slowing`) and its [active, activations, the memory
    slot of the vehicle the latest activation braked for]; the weave memory of each memory slot's
    vehicle (`controllers.weaving.WeaveMemory`: the way it moved across, the time it last turned
    back [s])."""

    lateral: np.ndarray
    speed_pi: np.ndarray
    seen: np.ndarray
    seen_speed: np.ndarray
    seen_slowing: np.ndarray
    flags: np.ndarray
    moving: np.ndarray
    weaved_at: np.ndarray


MEMORY_COLUMNS = (
    ("seen", 0),
    ("seen_speed", 0.0),
    ("seen_slowing", 0.0),
    ("moving", 0.0),
    ("weaved_at", -np.inf),
)
"""The per-vehicle memories of `ControllerArrays`, a column per memory slot, each with its empty value."""


class EgoLaws(NamedTuple):
    """The settings of the ego's per-tick laws, as the per-world controllers hold them: the lateral
    PID's gains, the cruise's speed PI and gap keeping, emergency braking's limits."""

    lateral: LateralGains
    speed: PIDTerms
    gap: GapKeeping
    braking: BrakingLimits


@dataclass(frozen=True, eq=False)
class ActedBatch:
    """Per world, one decision's outcome: control ticks run, whether the command was considered
    (no lane change ran), masked by the safety layer, refused by the maneuver, and the ego's mean
    speed over the ticks [m/s] (its speed when none ran)."""

    ticks: np.ndarray
    considered: np.ndarray
    masked: np.ndarray
    refused: np.ndarray
    mean_speed: np.ndarray
