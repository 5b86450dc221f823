"""The maneuver: lane keeping, or a lane change in progress towards a target lane, and the
reference it hands the controller every tick."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from numba.extending import register_jitable

from common.neighbours import lane_beyond, occupied_lanes
from controllers.leaders import leaders, road_to_leave
from controllers.reference import (
    QuinticProfile,
    WarpedProfile,
    clock_rate,
    drivable_duration,
    lane_change,
    lane_keeping,
)
from controllers.weaving import WeaveMemory
from records import Command, Reference, WorldState

AbortRule = Callable[[WorldState, int, int], bool]
"""(world, origin lane, target lane) -> True when a lane change from the one towards the other
must be given up."""


def never_abort(world: WorldState, lane: int, target: int) -> bool:
    return False


SETTLED_OFFSET = 0.05
"""How close [m] to its lane's centre the reference must be for a lane change to start from it."""


@register_jitable
def settled(d_reference: float, lane_centre: float) -> bool:
    """Whether the reference's lateral offset `d_reference` [m] has settled on `lane_centre` [m]:
    not so while an aborted change is still returning, when a new one would start from between
    lanes with its car possibly still pointing at the lane it gave up."""
    return abs(d_reference - lane_centre) <= SETTLED_OFFSET


@register_jitable
def lane_change_target(
    lane: int, shift: int, lanes_count: int, speed: float, min_speed: float, at_centre: bool
) -> int:
    """The lane a lane change `shift` lanes (-1 left, +1 right, 0 none) from `lane` heads for, or -1
    when none starts: no shift, off the road, the ego slower than `min_speed` [m/s], or the reference
    not yet `at_centre` of `lane` (`settled`)."""
    target = lane + shift
    if shift == 0 or not 0 <= target < lanes_count or speed < min_speed or not at_centre:
        return -1
    return target


@register_jitable
def left_origin(d: float, origin_offset: float, lane_width: float) -> bool:
    """Whether the ego's centre at lateral offset `d` [m] has left the origin lane centred at
    `origin_offset` [m]: past it, a lane change is no longer aborted."""
    return abs(d - origin_offset) > lane_width / 2


@dataclass(frozen=True)
class ManeuverCounts:
    """What the maneuver did in an episode: the lane changes it started (an aborted one included)."""

    lane_changes: int


class Maneuver:
    """Turns decisions into references. A lane change runs to its end (or is aborted by
    `should_abort` while the ego's centre is still in the origin lane); a command towards a lane
    that does not exist, or given below `min_speed`, is ignored. Speeds in m/s, durations in s,
    angles in rad.

    Drivable at any speed: a lane change lasts `duration`, or longer when the ego is slow, so the
    quintic's peak lateral speed stays within v tan(`max_course`) (`drivable_duration`); when the
    ego slows down during the change, the profile's clock slows with it (`WarpedProfile`, rate =
    v tan(max_course) / peak lateral speed, at most 1), so the course it asks for never exceeds
    `max_course` and a car that stops holds its lateral position until it moves again."""

    def __init__(
        self,
        world: WorldState,
        duration: float,
        set_speed: float,
        should_abort: AbortRule = never_abort,
        min_speed: float = 0.0,
        max_course: float = math.radians(12.0),
        cut_in_lookahead_s: float = 0.0,
        weaver_wary_s: float = 0.0,
    ) -> None:
        self.duration = duration
        self.cut_in_lookahead_s = cut_in_lookahead_s
        self.weaver_wary_s = weaver_wary_s
        self.set_speed = set_speed
        self.should_abort = should_abort
        self.min_speed = min_speed
        self.max_course = max_course
        self.lane = world.ego_lane
        self.target = self.lane
        self.profile = lane_keeping(float(world.lane_offsets[self.lane]), world.time)
        self.clock = WarpedProfile(self.profile)
        self.lane_changes = 0
        self.weaves = WeaveMemory()

    @property
    def changing_lane(self) -> bool:
        return self.target != self.lane

    @property
    def counts(self) -> ManeuverCounts:
        return ManeuverCounts(self.lane_changes)

    def command(self, command: Command, world: WorldState, start_time: float | None = None) -> bool:
        """Start the lane change `command` asks for, now or, planned ahead, at `start_time` [s]
        (the reference holds the lane until then, so a controller with preview sees it coming),
        from where the reference is now (its offset and lateral speed), so the reference stays
        smooth whatever the car's own tracking error; False when it is STAY, off the road, the
        ego is slower than `min_speed`, an aborted change is still returning, a lane change runs
        already or `start_time` is past."""
        speed = float(world.speed[0])
        d, d_dot, _ = self.clock.sample(world.time)
        at_centre = settled(d, float(world.lane_offsets[self.lane]))
        target = lane_change_target(
            self.lane, command.lane_shift, world.lanes_count, speed, self.min_speed, at_centre
        )
        if target < 0:
            return False
        if self.changing_lane or (start_time is not None and start_time < world.time):
            return False
        distance = float(world.lane_offsets[target]) - d
        self.profile = lane_change(
            world.lane_offsets,
            self.lane,
            target,
            d,
            world.time if start_time is None else start_time,
            drivable_duration(distance, max(speed, self.min_speed, 1e-3), self.duration, self.max_course),
            v0=d_dot,
        )
        self.clock = WarpedProfile(self.profile)
        self.target = target
        self.lane_changes += 1
        return True

    def reference(self, world: WorldState) -> Reference:
        """This tick's reference: aborts a lane change first when its gap has closed and its
        origin lane can be returned to (the abort rule handed in, `should_abort`), then samples
        the lateral profile and lists the leaders of the lane it heads for and of every other lane
        the ego's footprint reaches into: the origin lane until the footprint has left it (a
        stopped car there no longer holds a change that is past it), the abandoned lane while an
        aborted change returns."""
        if (
            self.changing_lane
            and not self._crossed(world)
            and self.should_abort(world, self.lane, self.target)
        ):
            self._abort(world)
        self.clock = self.clock.at_rate(world.time, self._rate(float(world.speed[0])))
        lanes = (self.target, *(lane for lane in occupied_lanes(world) if lane != self.target))
        heading_for = self.target if self.clock.profile_time(world.time) >= self.profile.t0 else self.lane
        leaving_lane, leaving_within, beyond = -1, math.inf, -1
        if self.changing_lane:
            beyond = lane_beyond(self.lane, self.target, world.lanes_count)
            profile = self.profile
            leaving_lane, leaving_within = self.lane, road_to_leave(
                tuple(profile.coefficients.tolist()), profile.t0, profile.duration, profile.d1,
                self.clock.profile_time(world.time), profile.peak_lateral_speed,
                float(world.lane_offsets[self.lane]), world.lane_width, float(world.width[0]),
                float(world.speed[0]), math.tan(self.max_course),
            )  # fmt: skip
        found = leaders(
            world, lanes, self.cut_in_lookahead_s, leaving_lane, leaving_within, beyond, self.weaves,
            self.weaver_wary_s,
        )  # fmt: skip
        return Reference.sampled(self.clock, world.time, self.set_speed, found, target_lane=heading_for)

    def _rate(self, speed: float) -> float:
        """How fast the profile's clock runs at `speed` [m/s] (see the class docstring)."""
        return clock_rate(speed, math.tan(self.max_course), self.profile.peak_lateral_speed)

    def update(self, world: WorldState) -> bool:
        """Advance the state machine; True on the tick a lane change completes."""
        if self.changing_lane and self.clock.finished(world.time):
            self.lane = self.target
            return True
        return False

    def _abort(self, world: WorldState) -> None:
        """Give up the lane change: a new quintic from the current lateral state back to the
        origin lane's centre, over half the lane-change duration."""
        _, d_dot, d_ddot = self.clock.sample(world.time)
        self.target = self.lane
        self.profile = QuinticProfile(
            d0=float(world.d[0]),
            d1=float(world.lane_offsets[self.lane]),
            t0=world.time,
            duration=self.duration / 2,
            v0=d_dot,
            a0=d_ddot,
        )
        self.clock = WarpedProfile(self.profile)

    def _crossed(self, world: WorldState) -> bool:
        """The ego's centre has left the origin lane."""
        return left_origin(float(world.d[0]), float(world.lane_offsets[self.lane]), world.lane_width)
