"""The maneuver: lane keeping, or a lane change in progress towards a target lane, and the
reference it hands the controller every tick."""

from __future__ import annotations

from collections.abc import Callable

from controllers.reference import QuinticProfile, lane_change, lane_keeping
from records import Command, Reference, WorldState

AbortRule = Callable[[WorldState, int], bool]
"""(world, target lane) -> True when a lane change towards that lane must be given up."""


def never_abort(world: WorldState, target: int) -> bool:
    return False


class Maneuver:
    """Turns decisions into references. A lane change runs to its end (or is aborted by
    `should_abort` while the ego's centre is still in the origin lane); a command towards a lane
    that does not exist is ignored. Speeds in m/s, durations in s."""

    def __init__(
        self, world: WorldState, duration: float, set_speed: float, should_abort: AbortRule = never_abort
    ) -> None:
        self.duration = duration
        self.set_speed = set_speed
        self.should_abort = should_abort
        self.lane = world.ego_lane
        self.target = self.lane
        self.profile = lane_keeping(float(world.lane_offsets[self.lane]), world.time)
        self.lane_changes = 0

    @property
    def changing_lane(self) -> bool:
        return self.target != self.lane

    def command(self, command: Command, world: WorldState, start_time: float | None = None) -> bool:
        """Start the lane change `command` asks for, now or, planned ahead, at `start_time` [s]
        (the reference holds the lane until then, so a controller with preview sees it coming);
        False when it is STAY or off the road."""
        target = self.lane + command.lane_shift
        if command is Command.STAY or not 0 <= target < world.lanes_count:
            return False
        ego = world.ego_state()
        self.profile = lane_change(
            world.lane_offsets,
            self.lane,
            target,
            ego.d,
            world.time if start_time is None else start_time,
            self.duration,
            v0=ego.d_dot,
        )
        self.target = target
        self.lane_changes += 1
        return True

    def reference(self, world: WorldState) -> Reference:
        """This tick's reference: aborts a lane change first when its gap has closed, then samples
        the lateral profile and lists the leaders of the occupied lanes."""
        if self.changing_lane and not self._crossed(world) and self.should_abort(world, self.target):
            self._abort(world)
        lanes = (self.lane, self.target) if self.changing_lane else (self.lane,)
        heading_for = self.target if world.time >= self.profile.t0 else self.lane
        return Reference.sampled(
            self.profile, world.time, self.set_speed, world.leaders(lanes), target_lane=heading_for
        )

    def update(self, world: WorldState) -> bool:
        """Advance the state machine; True on the tick a lane change completes."""
        if self.changing_lane and self.profile.finished(world.time):
            self.lane = self.target
            return True
        return False

    def _abort(self, world: WorldState) -> None:
        """Give up the lane change: a new quintic from the current lateral state back to the
        origin lane's centre, over half the lane-change duration."""
        _, d_dot, d_ddot = self.profile.sample(world.time)
        self.target = self.lane
        self.profile = QuinticProfile(
            d0=float(world.d[0]),
            d1=float(world.lane_offsets[self.lane]),
            t0=world.time,
            duration=self.duration / 2,
            v0=d_dot,
            a0=d_ddot,
        )

    def _crossed(self, world: WorldState) -> bool:
        """The ego's centre has left the origin lane."""
        return abs(world.d[0] - world.lane_offsets[self.lane]) > world.lane_width / 2
