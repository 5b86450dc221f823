"""The reference driver of the safety assessment: UN R157's "careful and competent human driver"
(Annex 4, Appendix 3, paragraph 3: the performance model for traffic disturbance scenarios),
driving the stack's own plant with the stack's own braking limit.

R157's model: the driver perceives the risk 0.4 s after it begins (risk perception time), starts
braking 0.75 s later (reaction time), and the deceleration ramps up to its maximum in 0.6 s
(R157: 0.774 g; here the plant's 5 m/s^2, ContinuousAction's limit, so a point is preventable
when a human would avoid the collision *in this vehicle*). A risk begins when a vehicle ahead
in the ego's or a neighbouring lane leaves the wandering zone of its lane (its centre more than
0.375 m from its lane's centre: a cut-in or a cut-out starts) or the vehicle ahead in the ego's
lane brakes harder than `BRAKE_LIGHT_MPS2`. The driver keeps its lane and speed until it
reacts, then brakes while it closes in on any vehicle ahead reaching into its lane.

A driver that `keeps_distance` (the replay that decides a collision's fault, `stack.fault.preventability`)
also perceives a risk when it closes in on the leader of its lane within R157's minimum following
distance (`common.r157`): a careful driver does not drive up to a slower vehicle unawares.
"""

from __future__ import annotations

import math

import numpy as np

from common.r157 import r157_min_following_distance
from records import Actuation, WorldState

RISK_PERCEPTION_S = 0.4
"""R157's risk perception time [s]."""
REACTION_S = 0.75
"""R157's reaction time, from perception to the start of braking [s]."""
RAMP_S = 0.6
"""R157's time for the deceleration to reach its maximum [s]."""
WANDERING_M = 0.375
"""R157's lateral wandering zone: how far a vehicle may drift from its lane centre unnoticed [m]."""
BRAKE_LIGHT_MPS2 = 1.0
"""A leader decelerating harder than this is seen braking [m/s^2]."""
PLANT_MAX_DECELERATION = 5.0
"""The plant's braking limit (highway-env ContinuousAction) [m/s^2]."""


class CarefulDriver:
    """R157's careful and competent driver as a longitudinal controller (steering 0: the straight
    road's lane is kept without it). `step(world, dt)` is one control tick of `dt` [s]; with
    `keeps_distance`, closing in within R157's minimum following distance is a risk too."""

    def __init__(
        self, max_deceleration: float = PLANT_MAX_DECELERATION, keeps_distance: bool = False
    ) -> None:
        self.max_deceleration = max_deceleration
        self.keeps_distance = keeps_distance
        self.reset()

    def reset(self) -> None:
        self.risk_at: float | None = None
        self.speeds: dict[int, float] = {}

    @property
    def delay_s(self) -> float:
        """Risk perception plus reaction [s]."""
        return RISK_PERCEPTION_S + REACTION_S

    def deceleration(self, time: float) -> float:
        """The braking the driver applies at `time` [s] when it brakes [m/s^2]: 0 before the delay,
        then a linear ramp to the maximum over RAMP_S."""
        if self.risk_at is None:
            return 0.0
        ramp = (time - self.risk_at - self.delay_s) / RAMP_S
        return self.max_deceleration * float(np.clip(ramp, 0.0, 1.0))

    def step(self, world: WorldState, dt: float) -> Actuation:
        if self.risk_at is None and self._risk(world, dt):
            self.risk_at = world.time
        self.speeds = {int(i): float(v) for i, v in zip(world.ids[1:], world.speed[1:], strict=True)}
        speed = float(world.speed[0])
        closing = any(speed > other for other in self._in_lane_speeds(world))
        braking = self.deceleration(world.time) if closing else 0.0
        return Actuation(acceleration=-min(braking, speed / dt), steering=0.0)

    def _in_lane_speeds(self, world: WorldState) -> list[float]:
        """Speeds [m/s] of the vehicles ahead whose footprint reaches into the ego's lane."""
        centre = float(world.lane_offsets[world.ego_lane])
        reach = (world.lane_width + world.width[1:]) / 2
        ahead = (world.s[1:] > world.s[0]) & (np.abs(world.d[1:] - centre) < reach)
        return [float(v) for v in world.speed[1:][ahead]]

    def _risk(self, world: WorldState, dt: float) -> bool:
        """A vehicle ahead left its wandering zone, or the ego lane's leader brakes (or, keeping
        distance, is closed in on within R157's minimum following distance)."""
        ego_lane = world.ego_lane
        for row in range(1, world.count):
            if world.s[row] <= world.s[0] or abs(int(world.lane[row]) - ego_lane) > 1:
                continue
            drift = abs(float(world.d[row] - world.lane_offsets[int(world.lane[row])]))
            if drift > WANDERING_M:
                return True
        leader = self._leader_row(world)
        if leader is not None and self.keeps_distance and self._too_close(world, leader):
            return True
        if leader is not None and (before := self.speeds.get(int(world.ids[leader]))) is not None:
            return (before - float(world.speed[leader])) / dt > BRAKE_LIGHT_MPS2
        return False

    def _too_close(self, world: WorldState, leader: int) -> bool:
        """Closing in on `leader` (a row) within R157's minimum following distance."""
        speed = float(world.speed[0])
        gap = float(world.s[leader] - world.s[0]) - float(world.length[leader] + world.length[0]) / 2
        return speed > float(world.speed[leader]) and gap < r157_min_following_distance(speed)

    def _leader_row(self, world: WorldState) -> int | None:
        """Row of the closest vehicle ahead in the ego's lane."""
        rows = [
            r for r in range(1, world.count) if world.lane[r] == world.ego_lane and world.s[r] > world.s[0]
        ]
        return min(rows, key=lambda r: float(world.s[r])) if rows else None


def stopping_distance(speed: float, delay_s: float, ramp_s: float, deceleration: float) -> float:
    """Distance [m] to standstill from `speed` [m/s]: `delay_s` at constant speed, a linear ramp to
    `deceleration` [m/s^2] over `ramp_s`, then full braking (continuous time)."""
    ramp_drop = deceleration * ramp_s / 2
    if ramp_drop >= speed:
        ramp_time = math.sqrt(2 * speed * ramp_s / deceleration)
        return speed * delay_s + speed * ramp_time - deceleration * ramp_time**3 / (6 * ramp_s)
    ramp = speed * ramp_s - deceleration * ramp_s**2 / 6
    return speed * delay_s + ramp + (speed - ramp_drop) ** 2 / (2 * deceleration)
