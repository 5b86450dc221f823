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

In traffic (`TrafficCarefulDriver`, the replay that decides a collision's fault,
`stack.fault.preventability`) the same driver meets many vehicles, and R157's model is applied to
each: a risk belongs to a vehicle (the one that leaves its wandering zone, or that a cut-out
reveals, or the leader that brakes or is closed in on within R157's minimum following distance,
`common.r157`), and the driver brakes for that vehicle only after its own perception and reaction
time and ramp, as hard as it must not to come nearer than that distance. It heeds only vehicles
near enough to matter (`TrafficCarefulDriver.heeds`): a lane change a kilometre ahead is no risk,
and an earlier risk elsewhere does not let it brake for a later cut-in sooner than R157 allows.
"""

from __future__ import annotations

import math

import numpy as np

from common.neighbours import WANDERING_M
from common.r157 import r157_min_following_distance
from records import Actuation, WorldState

RISK_PERCEPTION_S = 0.4
"""R157's risk perception time [s]."""
REACTION_S = 0.75
"""R157's reaction time, from perception to the start of braking [s]."""
RAMP_S = 0.6
"""R157's time for the deceleration to reach its maximum [s]."""
BRAKE_LIGHT_MPS2 = 1.0
"""A leader decelerating harder than this is seen braking [m/s^2]."""
STANDSTILL_GAP_M = 2.0
"""The gap a careful driver in traffic leaves to the vehicle ahead where R157 sets no distance
(below 7.2 km/h) [m]."""
PLANT_MAX_DECELERATION = 5.0
"""The plant's braking limit (highway-env ContinuousAction) [m/s^2]."""


def in_wandering_zone(world: WorldState, row: int, lane: int | None = None) -> bool:
    """Whether the centre of the vehicle in `row` is within `WANDERING_M` of the centre of `lane`
    (default: the lane it is in)."""
    lane = int(world.lane[row]) if lane is None else lane
    return abs(float(world.d[row] - world.lane_offsets[lane])) <= WANDERING_M


class CarefulDriver:
    """R157's careful and competent driver as a longitudinal controller (steering 0: the straight
    road's lane is kept without it), for the assessment's scenarios: one risk, the first, and full
    braking while closing in on any vehicle ahead. `step(world, dt)` is one control tick of `dt`
    [s]."""

    def __init__(self, max_deceleration: float = PLANT_MAX_DECELERATION) -> None:
        self.max_deceleration = max_deceleration
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
        return 0.0 if self.risk_at is None else self.ramped(time - self.risk_at)

    def ramped(self, since_risk_s: float) -> float:
        """The braking [m/s^2] available `since_risk_s` [s] after a risk began: 0 before the delay,
        then a linear ramp to the maximum over RAMP_S."""
        ramp = (since_risk_s - self.delay_s) / RAMP_S
        return self.max_deceleration * float(np.clip(ramp, 0.0, 1.0))

    def step(self, world: WorldState, dt: float) -> Actuation:
        if self.risk_at is None and self._risk(world, dt):
            self.risk_at = world.time
        self.speeds = {int(i): float(v) for i, v in zip(world.ids[1:], world.speed[1:], strict=True)}
        speed = float(world.speed[0])
        closing = any(speed > world.speed[row] for row in self._in_lane_rows(world))
        braking = self.deceleration(world.time) if closing else 0.0
        return Actuation(acceleration=-min(braking, speed / dt), steering=0.0)

    def _in_lane_rows(self, world: WorldState) -> list[int]:
        """Rows of the vehicles ahead whose footprint reaches into the ego's lane."""
        centre = float(world.lane_offsets[world.ego_lane])
        reach = (world.lane_width + world.width[1:]) / 2
        ahead = (world.s[1:] > world.s[0]) & (np.abs(world.d[1:] - centre) < reach)
        return [int(row) + 1 for row in np.flatnonzero(ahead)]

    def _risk(self, world: WorldState, dt: float) -> bool:
        """A vehicle ahead left its wandering zone, or the ego lane's leader brakes."""
        ego_lane = world.ego_lane
        for row in range(1, world.count):
            if world.s[row] <= world.s[0] or abs(int(world.lane[row]) - ego_lane) > 1:
                continue
            if not in_wandering_zone(world, row):
                return True
        leader = self._leader_row(world)
        if leader is not None and (before := self.speeds.get(int(world.ids[leader]))) is not None:
            return (before - float(world.speed[leader])) / dt > BRAKE_LIGHT_MPS2
        return False

    def _leader_row(self, world: WorldState) -> int | None:
        """Row of the closest vehicle ahead in the ego's lane."""
        rows = [
            r for r in range(1, world.count) if world.lane[r] == world.ego_lane and world.s[r] > world.s[0]
        ]
        return min(rows, key=lambda r: float(world.s[r])) if rows else None


class TrafficCarefulDriver(CarefulDriver):
    """R157's careful driver among many vehicles (module docstring): each risk is a vehicle's, with
    its own perception, reaction and ramp, and ends once that vehicle has settled in another lane
    than the ego's (a later maneuver of it is a new risk); only vehicles it `heeds` count; it brakes
    as hard as it must (`needed`) to keep `kept_distance` to the vehicles at risk ahead in its
    lane."""

    def reset(self) -> None:
        super().reset()
        self.risks: dict[int, float] = {}
        """Vehicle id -> the time its risk began [s]."""

    def step(self, world: WorldState, dt: float) -> Actuation:
        risky = self._risky(world, dt)
        for vehicle in risky:
            self.risks.setdefault(vehicle, world.time)
        for row in range(1, world.count):
            vehicle, lane = int(world.ids[row]), int(world.lane[row])
            settled = in_wandering_zone(world, row)
            if vehicle in self.risks and vehicle not in risky and settled and lane != world.ego_lane:
                del self.risks[vehicle]
        self.speeds = {int(i): float(v) for i, v in zip(world.ids[1:], world.speed[1:], strict=True)}
        braking = max(
            (
                min(self.ramped(world.time - self.risks[int(world.ids[row])]), self.needed(world, row))
                for row in self._in_lane_rows(world)
                if int(world.ids[row]) in self.risks and self.heeds(world, row)
            ),
            default=0.0,
        )
        speed = float(world.speed[0])
        return Actuation(acceleration=-min(braking, speed / dt), steering=0.0)

    def needed(self, world: WorldState, row: int) -> float:
        """The deceleration [m/s^2] that sheds the ego's closing speed on the vehicle in `row`
        before it is nearer than `kept_distance`: closing^2 / 2 (gap - kept), unbounded (full
        braking) once within it; 0 when not closing in."""
        speed = float(world.speed[0])
        closing = speed - float(world.speed[row])
        if closing <= 0:
            return 0.0
        room = _gap(world, row) - kept_distance(speed)
        return closing**2 / (2 * room) if room > 0 else math.inf

    def heeds(self, world: WorldState, row: int) -> bool:
        """Whether the vehicle in `row`, ahead, is near enough to matter: its gap [m] is below the
        road covered in `delay_s` at the ego's speed, plus `kept_distance`, plus closing^2 / 2
        `max_deceleration` when the ego is faster."""
        speed = float(world.speed[0])
        closing = max(speed - float(world.speed[row]), 0.0)
        reach = speed * self.delay_s + kept_distance(speed) + closing**2 / (2 * self.max_deceleration)
        return _gap(world, row) < reach

    def _risky(self, world: WorldState, dt: float) -> list[int]:
        """Ids of the vehicles whose risk begins or goes on now: a heeded vehicle ahead, in the
        ego's or a neighbouring lane, outside its wandering zone, and when it is in the ego's lane
        (a cut-out) every vehicle ahead of it there that it reveals; the ego lane's leader when it
        brakes or is closed in on within R157's minimum following distance."""
        ego_lane, risky = world.ego_lane, []
        in_lane = self._in_lane_rows(world)
        for row in range(1, world.count):
            lane = int(world.lane[row])
            if world.s[row] <= world.s[0] or abs(lane - ego_lane) > 1 or not self.heeds(world, row):
                continue
            if not in_wandering_zone(world, row):
                risky.append(int(world.ids[row]))
                if lane == ego_lane:
                    risky += [
                        int(world.ids[r])
                        for r in in_lane
                        if world.s[r] > world.s[row] and self.heeds(world, r)
                    ]
        leader = self._leader_row(world)
        if leader is not None:
            before = self.speeds.get(int(world.ids[leader]))
            braking = before is not None and (before - float(world.speed[leader])) / dt > BRAKE_LIGHT_MPS2
            speed = float(world.speed[0])
            close = speed > float(world.speed[leader]) and _gap(world, leader) < r157_min_following_distance(
                speed
            )
            if braking or close:
                risky.append(int(world.ids[leader]))
        return risky


def kept_distance(speed: float) -> float:
    """The distance [m] a careful driver keeps in traffic at `speed` [m/s]: R157's minimum following
    distance, at least `STANDSTILL_GAP_M`."""
    return max(r157_min_following_distance(speed), STANDSTILL_GAP_M)


def _gap(world: WorldState, row: int) -> float:
    """Bumper-to-bumper gap [m] from the ego to the vehicle in `row` ahead."""
    return float(world.s[row] - world.s[0]) - float(world.length[row] + world.length[0]) / 2


def stopping_distance(speed: float, delay_s: float, ramp_s: float, deceleration: float) -> float:
    """Distance [m] to standstill from `speed` [m/s]: `delay_s` at constant speed, a linear ramp to
    `deceleration` [m/s^2] over `ramp_s`, then full braking (continuous time)."""
    ramp_drop = deceleration * ramp_s / 2
    if ramp_drop >= speed:
        ramp_time = math.sqrt(2 * speed * ramp_s / deceleration)
        return speed * delay_s + speed * ramp_time - deceleration * ramp_time**3 / (6 * ramp_s)
    ramp = speed * ramp_s - deceleration * ramp_s**2 / 6
    return speed * delay_s + ramp + (speed - ramp_drop) ** 2 / (2 * deceleration)
