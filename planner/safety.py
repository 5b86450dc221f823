"""The safety layer (beyond the paper, standard in ADAS): no lane change into a lane that does
not exist or into an unsafe gap, and abort a lane change whose gap closes.

A gap is safe when, in the target lane, the vehicle ahead is at least
max(min_gap, front_time_gap * v_ego) away and the ego would not reach it within min_ttc, and the
vehicle behind is at least max(min_gap, rear_time_gap * v_rear) away and would not reach the ego
within min_ttc. An abort uses the looser abort_gap / abort_ttc, so a change is not abandoned for
the margin that made it start; it counts in the target lane every vehicle whose present sideways
motion carries it there within abort_lookahead (a car cutting in from the far lane is met before
it arrives, while the ego can still turn back). No change starts while a vehicle in the lane beyond
the target is within far_lane_gap of the ego, bumper to bumper: alongside, it may take the same
gap at the same moment, and a change under way cannot get out of its way (at 4 m/s an abort needs
seconds to turn back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field

from common.neighbours import lateral_drift, neighbours, scanned_neighbours
from records import Command, Neighbour, WorldState

MAX_GAP_M = 200.0
"""Largest gap the safety layer may ask for [m]: beyond any sensor's reach on a highway."""
MAX_TIME_S = 60.0
"""Largest time gap or time to collision it may ask for [s]."""


class SafetyConfig(BaseModel):
    """Gaps in m, time gaps and TTCs in s, each bounded (`MAX_GAP_M`, `MAX_TIME_S`)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    enabled: bool = True
    min_gap_m: float = Field(6.0, ge=0, le=MAX_GAP_M, description="smallest gap to change into [m]")
    front_time_gap_s: float = Field(0.8, ge=0, le=MAX_TIME_S, description="to the car ahead [s]")
    rear_time_gap_s: float = Field(0.8, ge=0, le=MAX_TIME_S, description="for the car behind [s]")
    min_ttc_s: float = Field(4.0, ge=0, le=MAX_TIME_S, description="smallest time to collision [s]")
    abort_gap_m: float = Field(2.0, ge=0, le=MAX_GAP_M, description="gap that aborts a change [m]")
    abort_ttc_s: float = Field(1.5, ge=0, le=MAX_TIME_S, description="TTC that aborts a change [s]")
    abort_lookahead_s: float = Field(
        1.0, ge=0, le=MAX_TIME_S, description="an abort sees a car cutting in this early [s]"
    )
    far_lane_gap_m: float | None = Field(
        2.0,
        ge=0,
        le=MAX_GAP_M,
        description="no change starts while a vehicle in the lane beyond the target is this close, "
        "bumper to bumper [m] (none: no such check)",
    )


def _ttc(gap: float, closing: float) -> float:
    return math.inf if closing <= 0 else max(gap, 0.0) / closing


def unsafe_neighbours(
    config: SafetyConfig,
    speed: float,
    ahead: Neighbour | None,
    behind: Neighbour | None,
    min_gap: float,
    min_ttc: float,
    strict: bool,
) -> tuple[int, ...]:
    """The vehicles (ids) of `ahead` and `behind` closer than the gap [m] or TTC [s] allows for an
    ego at `speed` [m/s]: the gap rule of the module docstring (time gaps only when `strict`); none
    when the lane is safe. What a planner that checks gaps itself uses too."""
    unsafe: tuple[int, ...] = ()
    if ahead is not None and not _clear(
        ahead, max(min_gap, config.front_time_gap_s * speed * strict), speed - ahead.speed, min_ttc
    ):
        unsafe += (ahead.vehicle,)
    if behind is not None and not _clear(
        behind, max(min_gap, config.rear_time_gap_s * behind.speed * strict), behind.speed - speed, min_ttc
    ):
        unsafe += (behind.vehicle,)
    return unsafe


def _clear(other: Neighbour, min_gap: float, closing: float, min_ttc: float) -> bool:
    return other.gap >= min_gap and _ttc(other.gap, closing) >= min_ttc


@dataclass(frozen=True)
class SafetyCounts:
    """What the safety layer did in an episode: commands it `masked` (replaced by STAY) and lane
    changes it `aborted`."""

    masked: int
    aborted: int


class SafetyLayer:
    """Masks unsafe commands and flags lane changes to abort; counts both. `reacted_to` holds the
    ids of the vehicles whose gap made it act last (a recording marks them)."""

    def __init__(self, config: SafetyConfig) -> None:
        self.config = config
        self.masked = 0
        self.aborted = 0
        self.reacted_to: tuple[int, ...] = ()

    @property
    def counts(self) -> SafetyCounts:
        return SafetyCounts(self.masked, self.aborted)

    def gap_is_safe(self, world: WorldState, lane: int, min_gap: float, min_ttc: float, strict: bool) -> bool:
        return not self.unsafe_neighbours(world, lane, min_gap, min_ttc, strict)

    def unsafe_neighbours(
        self,
        world: WorldState,
        lane: int,
        min_gap: float,
        min_ttc: float,
        strict: bool,
        lookahead_s: float = 0.0,
    ) -> tuple[int, ...]:
        """The vehicles (ids) ahead and behind in `lane` closer than the gap [m] or TTC [s] allows,
        counting those whose present lateral motion carries them into `lane` within `lookahead_s` [s]."""
        if lookahead_s > 0:
            ahead, behind = scanned_neighbours(world, lane, lateral_drift(world, lookahead_s))
        else:
            ahead, behind = neighbours(world, lane)
        return unsafe_neighbours(self.config, float(world.speed[0]), ahead, behind, min_gap, min_ttc, strict)

    def permits(self, command: Command, world: WorldState, lane: int) -> bool:
        """Whether `filter` lets `command` through (without counting a mask)."""
        if command is Command.STAY or not self.config.enabled:
            return True
        target = lane + command.lane_shift
        config = self.config
        return (
            0 <= target < world.lanes_count
            and self.gap_is_safe(world, target, config.min_gap_m, config.min_ttc_s, strict=True)
            and not self._alongside_beyond(world, target + command.lane_shift)
        )

    def _alongside_beyond(self, world: WorldState, far_lane: int) -> tuple[int, ...]:
        """The vehicles (ids) of `far_lane`, the lane beyond a change's target, closer to the ego
        than `far_lane_gap_m` (none without the check or the lane)."""
        gap = self.config.far_lane_gap_m
        if gap is None or not 0 <= far_lane < world.lanes_count:
            return ()
        return self.unsafe_neighbours(world, far_lane, gap, 0.0, strict=False)

    def filter(self, command: Command, world: WorldState, lane: int) -> Command:
        """`command`, or STAY when it leads off the road or into an unsafe gap."""
        if self.permits(command, world, lane):
            return command
        self.masked += 1
        target = lane + command.lane_shift
        config = self.config
        if 0 <= target < world.lanes_count:
            self.reacted_to = self.unsafe_neighbours(
                world, target, config.min_gap_m, config.min_ttc_s, True
            ) + self._alongside_beyond(world, target + command.lane_shift)
        else:
            self.reacted_to = ()
        return Command.STAY

    def should_abort(self, world: WorldState, target: int) -> bool:
        """True when the gap in `target` has closed below the abort margins, counting the vehicles
        that move into `target` within the abort's lookahead."""
        config = self.config
        if not config.enabled:
            return False
        gap, ttc = config.abort_gap_m, config.abort_ttc_s
        unsafe = self.unsafe_neighbours(world, target, gap, ttc, False, config.abort_lookahead_s)
        if unsafe:
            self.aborted += 1
            self.reacted_to = unsafe
        return bool(unsafe)
