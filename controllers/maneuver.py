"""The maneuver state machine: lane keeping, or a lane change in progress towards a target lane."""

from __future__ import annotations

import math

from controllers.reference import QuinticProfile, lane_change, lane_keeping
from perception.types import WorldState
from planner.command import Command


class Maneuver:
    """Turns decisions into lateral references. A lane change runs to its end before the next
    decision is taken; a command towards a lane that does not exist is ignored."""

    def __init__(self, world: WorldState, duration: float) -> None:
        self.duration = duration
        self.lane = int(world.lane[0])
        self.target = self.lane
        self.profile = lane_keeping(float(world.lane_offsets[self.lane]), world.time)
        self.lane_changes = 0

    @property
    def changing_lane(self) -> bool:
        return self.target != self.lane

    def command(self, command: Command, world: WorldState) -> bool:
        """Start the lane change `command` asks for; False when it is STAY or off the road."""
        target = self.lane + command.lane_shift
        if command is Command.STAY or not 0 <= target < world.lanes_count:
            return False
        ego = world.ego
        lane_heading = world.lanes[self.lane].heading_at(ego.s)
        self.profile = lane_change(
            world.lane_offsets,
            self.lane,
            target,
            ego.d,
            world.time,
            self.duration,
            v0=ego.speed * math.sin(ego.heading - lane_heading),
        )
        self.target = target
        self.lane_changes += 1
        return True

    def abort(self, world: WorldState) -> None:
        """Give up the lane change: a new quintic from the current lateral state back to the
        origin lane's centre, over half the lane-change duration."""
        ego = world.ego
        d, d_dot, d_ddot = self.profile.sample(world.time)
        self.target = self.lane
        self.profile = QuinticProfile(
            d0=ego.d,
            d1=float(world.lane_offsets[self.lane]),
            t0=world.time,
            duration=self.duration / 2,
            v0=d_dot,
            a0=d_ddot,
        )

    def crossed(self, world: WorldState) -> bool:
        """The ego's centre has left the origin lane."""
        return abs(world.ego.d - world.lane_offsets[self.lane]) > world.lane_width / 2

    def update(self, world: WorldState) -> bool:
        """Advance the state machine; True on the tick a lane change completes."""
        if self.changing_lane and self.profile.finished(world.time):
            self.lane = self.target
            return True
        return False

    def reference(self, time: float) -> tuple[float, float, float]:
        """(d, d_dot, d_ddot) of the lateral reference at `time`."""
        return self.profile.sample(time)

    @property
    def occupied_lanes(self) -> tuple[int, ...]:
        """The lanes whose leaders matter: the own lane and, during a change, the target lane."""
        return (self.lane, self.target) if self.changing_lane else (self.lane,)
