"""Who is at fault in a collision, as UN R157 decides preventability: a collision is the ego's fault
unless a careful and competent driver in its place could not have avoided it either.

- The ego's own lane change (the geometric `lane change` contact, or the ego's lane differing
  anywhere in the last `REPLAY_S` seconds, unless the collided vehicle's cut-in began only after
  the ego's centre was in its new lane: a driver entering a lane yields to those already in it)
  and leaving the road stay at fault: no replay excuses a maneuver the ego chose. A vehicle that
  came at the ego from the side its change moved away from (it crossed into the lane the ego was
  leaving) is no such maneuver's: that contact is replayed (a side or rear contact as a side
  swipe: the ego was not keeping its lane).
- Being hit from behind or standing (`rear`, `ego stopped`) while keeping its lane is the other's:
  the follower's recorded path answered the ego's own braking, so no replay can judge it.
- Any other contact (front, stopped vehicle, side swipe) is replayed: R157's reference driver in
  traffic (`stack.fault.reference_driver.TrafficCarefulDriver`: for each vehicle's risk, perception
  0.4 s, reaction 0.75 s, a 0.6 s ramp to the plant's 5 m/s^2; keeping R157's minimum following
  distance; heeding the vehicles near enough to matter) takes the ego's place `REPLAY_S` seconds
  before the contact, at the ego's position and speed then, keeps the ego's path across the road
  and drives as the ego drove until it first brakes, against the other vehicles' recorded
  trajectories, and for `BEYOND_S` past the contact's time against them extrapolated (each holding
  its last acceleration; one moving sideways goes on to the next lane's centre). If it touches
  nobody, the collision was preventable: at fault. The other vehicles replay what they did; they do
  not react to the reference driver, so after a frontal contact only vehicles ahead of it count (a
  recorded follower that followed the ego elsewhere is no evidence), after being hit from behind or
  side on every vehicle counts.

The reason says why: the situation (the collided vehicle's cut-in within the replayed seconds, by
emergency braking's attribution law, `stack.fault.emergency_causes`; for a vehicle ahead, its hard
braking; else the contact's kind, rear, side swipe, ego stopped or stopped vehicle, or closing in)
and whether it was preventable ("cut-in not preventable", "leader braking preventable"); "own lane change" and
"off road" for the maneuvers that stay at fault."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from common.neighbours import turned_width
from records import WorldState
from stack.fault.emergency_causes import CLOSING_IN, NEVER, CauseTracker, cause_label, emergency_cause
from stack.fault.reference_driver import TrafficCarefulDriver, in_wandering_zone
from stack.sim.batch.traffic_frame import Body

REPLAY_S = 5.0
"""How long before the contact the reference driver takes the ego's place [s]."""
BEYOND_S = 8.0
"""How long after the contact's time the replay goes on, the others extrapolated [s]: a contact
only just avoided at that time may still come (a follower still closing in on a reference driver
that stands)."""
TURNING_BACK_S = 1.0
"""How far back the ego's recent sideways motion is read [s]: an ego that moved away from a vehicle
over the replayed seconds but turned back towards it since (an aborted change) went to meet it."""
FROM_BEHIND_KINDS = ("rear", "side swipe", "ego stopped")
"""Contact kinds where the other vehicle came into the ego: the replay counts every vehicle."""
HIT_FROM_BEHIND_KINDS = ("rear", "ego stopped")
"""Contact kinds the replay cannot judge: the vehicle that hit the ego from behind (or hit it
standing) drove its recorded path in answer to the ego's own braking, so a reference driver that
brakes otherwise meets a follower that would have driven otherwise. Without a lane change of the
ego's in the replayed seconds, such a contact is the other's (as R157 and nuPlan take it)."""


@dataclass(frozen=True)
class Fault:
    """The verdict on a collision: whether the ego is at fault, and why (module docstring)."""

    at_fault: bool
    reason: str


class WorldHistory:
    """The truth of the last `REPLAY_S` seconds (plus the frame now), one snapshot a tick: bounded
    memory. Snapshots are records, never changed: a copy of the history (a fork of the loop)
    shares them."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.worlds: deque[WorldState] = deque(maxlen=round(REPLAY_S / dt) + 1)

    def add(self, world: WorldState) -> None:
        self.worlds.append(world)

    def __deepcopy__(self, memo: dict[int, Any]) -> WorldHistory:
        copied = WorldHistory(self.dt)
        copied.worlds = deque(self.worlds, maxlen=self.worlds.maxlen)
        memo[id(self)] = copied
        return copied


def judge(kind: str, other: int | None, history: Sequence[WorldState], dt: float) -> Fault:
    """The fault of the collision of geometric `kind` (`stack.loop.safety_metrics`) with the vehicle
    of id `other` (None: unknown), at the last of `history` (the truth, one snapshot a tick of `dt`
    [s], oldest first)."""
    if kind == "off road":
        return Fault(True, "off road")
    crash = history[-1]
    situation = _situation(other, history, dt)
    changed = kind == "lane change" or any(world.ego_lane != crash.ego_lane for world in history)
    entered_first = situation == "cut-in" and _in_the_lane_before_cut_in(other, history)
    if changed and not entered_first:
        if not _came_from_the_side_left(other, history, dt):
            return Fault(True, "own lane change")
        kind = "side swipe" if kind == "rear" else kind
    kind = "side swipe" if kind == "lane change" else kind
    if kind in HIT_FROM_BEHIND_KINDS:
        return Fault(False, f"{kind} not preventable")
    from_behind = kind in FROM_BEHIND_KINDS
    if (from_behind and situation != "cut-in") or (kind == "stopped vehicle" and situation == "closing in"):
        situation = kind
    avoided = careful_driver_avoids(history, dt, from_behind)
    return Fault(avoided, f"{situation} {'preventable' if avoided else 'not preventable'}")


def _in_the_lane_before_cut_in(other: int | None, history: Sequence[WorldState]) -> bool:
    """Whether the ego was in its new lane before the vehicle of id `other` began the cut-in that
    ended in the contact: after the last frame of `history` in which that vehicle kept a lane other
    than the one the ego collided in (its centre within that lane's wandering zone), the ego's
    centre is in the lane it collided in on every frame. The other then entered a lane the ego was
    already in (from the far side too, across two lanes), which the ego's choice did not cause."""
    lane = history[-1].ego_lane
    cut_from = None
    for index, world in enumerate(history):
        rows = np.flatnonzero(world.ids == other)
        if rows.size:
            row, its_lane = int(rows[0]), int(world.lane[int(rows[0])])
            cut_from = index + 1 if in_wandering_zone(world, row) and its_lane != lane else cut_from
    if cut_from is None:
        return False
    return all(world.ego_lane == lane for world in list(history)[cut_from:])


def _came_from_the_side_left(other: int | None, history: Sequence[WorldState], dt: float) -> bool:
    """Whether the vehicle of id `other` came at the ego from the side its lane change moved away
    from: over `history` the ego's centre moved across the road one way (and did not turn back over
    its last `TURNING_BACK_S`), and at the contact the other's centre lies the other way. Such a
    vehicle crossed into the lane the ego was leaving: the ego's maneuver did not take it there, and
    the contact is judged by the replay, as a side swipe."""
    crash = history[-1]
    rows = np.flatnonzero(crash.ids == other)
    if not rows.size:
        return False
    recent = history[-min(len(history), round(TURNING_BACK_S / dt) + 1)]
    side = float(crash.d[int(rows[0])] - crash.d[0])
    moved, lately = float(crash.d[0] - history[0].d[0]), float(crash.d[0] - recent.d[0])
    return moved * side < 0 and lately * side <= 0


def _situation(other: int | None, history: Sequence[WorldState], dt: float) -> str:
    """What the vehicle of id `other` did before the contact, as emergency braking's cause law
    reads it over `history` (`CauseTracker`): cut-in, leader braking or closing in."""
    tracker = CauseTracker(dt)
    for world in history:
        tracker.observe(world)
    column = tracker.columns.get(-1 if other is None else other)
    if column is None:
        return cause_label(CLOSING_IN)
    drifted_at, braked_at = float(tracker.drifted_at[column]), float(tracker.braked_at[column])
    return cause_label(emergency_cause(False, history[-1].time, drifted_at, braked_at, NEVER, REPLAY_S))


def careful_driver_avoids(history: Sequence[WorldState], dt: float, from_behind: bool) -> bool:
    """Whether R157's reference driver, in the ego's place from the first of `history` (its position
    and speed then), touches no vehicle of the recorded frames and of their extrapolation
    (`extrapolated`, `BEYOND_S`; only vehicles ahead of it count unless the contact came
    `from_behind`). It keeps the ego's path across the road (its recorded lateral position and
    lane; past the contact, the centre of the lane it collided in), and drives as the ego drove
    along it (the ego's recorded speed; past the contact, it holds its speed) until it first brakes
    for a risk, and from then on only brakes or holds its speed: a careful driver in the ego's
    place, not one that never sped up or that was elsewhere. Its position is the ego's recorded
    one less how far it fell behind (the speeds' difference integrated), so where it drove as the
    ego did it is exactly where the ego was, whatever the plant's integration."""
    driver = TrafficCarefulDriver()
    start, crash = history[0], history[-1]
    frames = [*history, *extrapolated(history, dt, BEYOND_S)]
    path = [(float(world.d[0]), world.ego_lane) for world in history]
    path += [(float(crash.lane_offsets[crash.ego_lane]), crash.ego_lane)] * (len(frames) - len(history))
    speed, behind, reacted = float(start.speed[0]), 0.0, False
    for tick, world in enumerate(frames):
        d, lane = path[tick]
        placed = _with_ego(world, float(world.s[0]) - behind, d, speed, lane)
        if touches(placed, from_behind, dt):
            return False
        braking = driver.step(placed, dt).acceleration
        reacted = reacted or braking < 0
        behind += (float(world.speed[0]) - speed) * dt
        if reacted:
            speed = max(speed + braking * dt, 0.0)
        elif tick + 1 < len(history):
            speed = float(history[tick + 1].speed[0])
    return True


def extrapolated(history: Sequence[WorldState], dt: float, seconds: float) -> list[WorldState]:
    """Frames every `dt` [s] for `seconds` after the last of `history`: each vehicle holds the
    acceleration of its last tick (speed at least 0), and one that moved sideways on its last tick
    goes on at that lateral speed to the centre of the next lane in that direction."""
    last = history[-1]
    before = history[-2] if len(history) > 1 else last
    rows = {int(vehicle): row for row, vehicle in enumerate(before.ids.tolist())}
    previous = [rows.get(int(vehicle)) for vehicle in last.ids.tolist()]
    s, d, speed = last.s.astype(float), last.d.astype(float), last.speed.astype(float)
    acceleration = np.array(
        [0.0 if r is None else (speed[k] - before.speed[r]) / dt for k, r in enumerate(previous)]
    )
    lateral = np.array([0.0 if r is None else (d[k] - before.d[r]) / dt for k, r in enumerate(previous)])
    offsets = np.sort(last.lane_offsets)
    goal = np.array([_next_centre(offsets, float(d[k]), float(lateral[k])) for k in range(last.count)])
    frames = []
    for tick in range(1, round(seconds / dt) + 1):
        s = s + speed * dt
        step = lateral * dt
        d = np.where(np.abs(goal - d) <= np.abs(step), goal, d + step)
        speed = np.maximum(speed + acceleration * dt, 0.0)
        lanes = np.abs(d[:, None] - last.lane_offsets[None, :]).argmin(axis=1)
        frames.append(replace(last, time=last.time + tick * dt, s=s, d=d, speed=speed, lane=lanes))
    return frames


def _next_centre(offsets: np.ndarray, d: float, lateral: float) -> float:
    """The first lane centre (of the sorted `offsets` [m]) at or beyond `d` in the direction of
    `lateral` [m/s]; `d` itself when it does not move sideways."""
    if abs(lateral) < 1e-6:
        return d
    ahead = offsets[offsets >= d - 1e-9] if lateral > 0 else offsets[offsets <= d + 1e-9][::-1]
    return float(ahead[0]) if ahead.size else d


def _with_ego(world: WorldState, s: float, d: float, speed: float, lane: int) -> WorldState:
    """`world` with the ego at `s`, `d` [m], `speed` [m/s] in lane `lane`, heading along it."""

    def first(values: np.ndarray, value: float) -> np.ndarray:
        changed = values.copy()
        changed[0] = value
        return changed

    return replace(
        world,
        s=first(world.s, s),
        d=first(world.d, d),
        speed=first(world.speed, speed),
        lane=first(world.lane, lane),
    )


def touches(world: WorldState, from_behind: bool, dt: float) -> bool:
    """The ego's footprint meets another's in the lane frame as the simulation counts a crash:
    highway-env's test (`RoadObject._is_colliding`: the rectangles turned by their headings to the
    lane, intersecting now or within one tick of `dt` [s] at their velocities; such a vehicle is
    pushed apart and marked crashed at its next step, so a recorded crash frame may show the two
    already apart), after a bounding-box test on their extents along and across the road widened
    by a tick's travel; only vehicles whose centre is ahead of the ego's count unless
    `from_behind`."""
    heading = world.heading - world.lanes[0].heading_at(float(world.s[0]))
    across = turned_width(world.length, world.width, heading)
    along = turned_width(world.width, world.length, heading)
    travel = (world.speed + world.speed[0]) * dt
    others = np.arange(1, world.count)
    near = (np.abs(world.s[others] - world.s[0]) < (along[others] + along[0]) / 2 + travel[others]) & (
        np.abs(world.d[others] - world.d[0]) < (across[others] + across[0]) / 2 + travel[others]
    )
    counted = np.ones(others.size, dtype=bool) if from_behind else world.s[others] > world.s[0]
    ego = _body(world, 0, heading)
    return any(
        any(ego._is_colliding(_body(world, row, heading), dt)[:2]) for row in others[near & counted].tolist()
    )


def _body(world: WorldState, row: int, heading: np.ndarray) -> Body:
    """The vehicle in `row` of `world` in the lane frame, as highway-env's collision test reads it."""
    length, width = float(world.length[row]), float(world.width[row])
    return Body(
        np.array([world.s[row], world.d[row]]), float(heading[row]), float(world.speed[row]), length, width,
        math.hypot(length, width),
    )  # fmt: skip
