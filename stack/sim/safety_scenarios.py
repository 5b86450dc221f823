"""The three logical scenarios of UN R157's traffic-disturbance assessment, each a parameter grid,
built as `ScriptedRoad` plants: the ego drives lane `EGO_LANE` of a straight road at its cruise
speed, no other traffic.

- **lead braking**: a leader `time_gap` x speed ahead (bumper to bumper), at the ego's speed,
  brakes at `deceleration` to standstill from `BRAKE_AT_S`.
- **cut-in**: a vehicle in the next lane, `relative_speed` slower than the ego, moves into the
  ego's lane at `lateral_speed` once the gap between them (bumper to bumper) is `gap`.
- **cut-out**: a leader at the default cruise gap (1.5 s + 8 m, shorter where the distance asks
  for it) moves to the next lane at `lateral_speed` once the ego is `distance` (bumper to bumper)
  from a stationary vehicle ahead of it, revealing that vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from highway_env.vehicle.kinematics import Vehicle

from records import PlantName
from stack.sim.scripted_road import EGO_START_S, LANE_WIDTH, Actor, ScriptedRoad

ScenarioKind = Literal["lead-braking", "cut-in", "cut-out"]
SCENARIO_KINDS: tuple[ScenarioKind, ...] = get_args(ScenarioKind)
EGO_LANE = 1
LENGTH = Vehicle.LENGTH
"""Every vehicle's length [m] (highway-env's 5 m)."""
BRAKE_AT_S = 1.0
"""When the lead-braking leader starts braking [s]."""
LEAD_IN_S = 1.0
"""How long a cut-in or cut-out vehicle drives before its move at a constant ego speed [s]."""
LEADER_TIME_GAP_S, LEADER_STANDSTILL_M = 1.5, 8.0
"""The cut-out leader's gap: the default cruise gap [s], [m]."""
DURATION_S = 40.0
"""Longest episode [s]; most end earlier, once the scenario has played out (`ScriptedRoad.done`)."""
KMH = 1 / 3.6
"""[m/s per km/h]"""

PARAMETERS: dict[ScenarioKind, tuple[tuple[str, str], ...]] = {
    "lead-braking": (("speed", "m/s"), ("time_gap", "s"), ("deceleration", "m/s^2")),
    "cut-in": (("speed", "m/s"), ("relative_speed", "m/s"), ("gap", "m"), ("lateral_speed", "m/s")),
    "cut-out": (("speed", "m/s"), ("distance", "m"), ("lateral_speed", "m/s")),
}
"""Each scenario's parameters (name, unit), in the order a point lists them."""
LIMITS = {
    "speed": 40.0,
    "time_gap": 10.0,
    "deceleration": 10.0,
    "relative_speed": 40.0,
    "gap": 500.0,
    "lateral_speed": 5.0,
    "distance": 500.0,
}
"""The largest value of each parameter a point may take (in its unit; the smallest is 0, the
speed's just above): the full grids and well past them, a bounded scenario."""
SPEEDS = tuple(round(kmh * KMH, 2) for kmh in (20, 30, 40, 50, 60, 70, 80, 100, 115, 130))
GRIDS: dict[ScenarioKind, tuple[tuple[float, ...], ...]] = {
    "lead-braking": (SPEEDS, (0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.5), (2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0)),
    "cut-in": (
        tuple(round(kmh * KMH, 2) for kmh in (30, 50, 70, 90, 110, 130)),
        (0.0, 2.0, 4.0, 6.0, 8.0),
        (3.0, 6.0, 10.0, 15.0, 25.0, 40.0),
        (0.5, 1.0, 1.5),
    ),
    "cut-out": (
        SPEEDS,
        (10.0, 20.0, 30.0, 45.0, 60.0, 80.0, 100.0, 130.0, 160.0, 200.0),
        (0.5, 1.0, 1.5, 2.0, 2.5),
    ),
}
"""The full grids: 560, 540 and 500 points."""
QUICK_GRIDS: dict[ScenarioKind, tuple[tuple[float, ...], ...]] = {
    "lead-braking": ((8.33, 22.22, 36.11), (0.8, 1.4, 2.0), (3.0, 5.0, 8.0)),
    "cut-in": ((13.89, 36.11), (0.0, 6.0), (3.0, 10.0, 25.0), (0.5, 1.5)),
    "cut-out": ((8.33, 22.22, 36.11), (20.0, 60.0, 130.0), (1.0, 2.5)),
}
"""The `--quick` grids: 27, 24 and 18 points."""


@dataclass(frozen=True)
class Point:
    """One concrete scenario: its kind and parameter values (in `PARAMETERS[kind]` order)."""

    kind: ScenarioKind
    values: tuple[float, ...]

    @property
    def parameters(self) -> dict[str, float]:
        return {name: value for (name, _), value in zip(PARAMETERS[self.kind], self.values, strict=True)}

    @property
    def text(self) -> str:
        """The point as `--point` takes it: name=value pairs, comma-separated."""
        return ",".join(f"{name}={value:g}" for name, value in self.parameters.items())


def grid(kind: ScenarioKind, quick: bool = False) -> list[Point]:
    """Every point of `kind`'s grid, in a fixed order."""
    axes = (QUICK_GRIDS if quick else GRIDS)[kind]
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    return [Point(kind, tuple(float(v) for v in row)) for row in mesh]


def parse_point(kind: ScenarioKind, text: str) -> Point:
    """The point `text` (`name=value,...`, every parameter of `kind` once) names; ValueError (one
    line) otherwise."""
    names = [name for name, _ in PARAMETERS[kind]]
    given: dict[str, float] = {}
    for entry in text.split(","):
        name, _, value = entry.partition("=")
        if name.strip() not in names:
            raise ValueError(f"expected {', '.join(f'{n}=VALUE' for n in names)} for {kind}, got {entry!r}")
        if name.strip() in given:
            raise ValueError(f"{name.strip()}: given twice; name each parameter of {kind} once")
        try:
            given[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if missing := [name for name in names if name not in given]:
        raise ValueError(f"missing {', '.join(missing)} for {kind}")
    for name, unit in PARAMETERS[kind]:
        number, positive = given[name], name == "speed"
        if not (0 < number if positive else 0 <= number) or not number <= LIMITS[name]:
            low = "(0" if positive else "[0"
            raise ValueError(f"{name} must be in {low}, {LIMITS[name]:g}] {unit}, got {number:g}")
    return Point(kind, tuple(given[name] for name in names))


def lane_centre(lane: int) -> float:
    return lane * LANE_WIDTH


class LeadBraking:
    """The leader brakes at `deceleration` [m/s^2] from `BRAKE_AT_S`."""

    def __init__(self, deceleration: float) -> None:
        self.deceleration = deceleration
        self.started_at: float | None = None
        self.gap_at_start = 0.0

    def update(self, time: float, ego_s: float, actors: list[Actor]) -> None:
        if self.started_at is None and time >= BRAKE_AT_S - 1e-9:
            actors[0].braking, self.started_at = self.deceleration, time
            self.gap_at_start = actors[0].s - ego_s - LENGTH

    def settled(self, actors: list[Actor]) -> bool:
        return self.started_at is not None and actors[0].speed == 0.0


class LaneMove:
    """Actor `mover` moves to lane `to_lane` at `lateral_speed` [m/s] once the ego's bumper gap to
    actor `watched` is at most `gap` [m], or actor 0 is within 1 m of actor 1 (cut-out)."""

    def __init__(self, mover: int, watched: int, gap: float, to_lane: int, lateral_speed: float) -> None:
        self.mover, self.watched, self.gap = mover, watched, gap
        self.to_lane, self.lateral_speed = to_lane, lateral_speed
        self.started_at: float | None = None
        self.gap_at_start = 0.0

    def update(self, time: float, ego_s: float, actors: list[Actor]) -> None:
        if self.started_at is not None:
            return
        gap = actors[self.watched].s - ego_s - LENGTH
        blocked = len(actors) > 1 and actors[1].s - actors[0].s - LENGTH <= 1.0
        if gap <= self.gap + 1e-9 or blocked:
            mover = actors[self.mover]
            mover.target_d, mover.lateral_speed = lane_centre(self.to_lane), self.lateral_speed
            self.started_at, self.gap_at_start = time, gap

    def settled(self, actors: list[Actor]) -> bool:
        mover = actors[self.mover]
        return self.started_at is not None and mover.d == mover.target_d


def build(point: Point, lanes: int, plant: PlantName, dt: float) -> ScriptedRoad:
    """`point` as a plant on a road of `lanes` lanes (at least 3)."""
    p = point.parameters
    speed, ego_front = p["speed"], EGO_START_S + LENGTH / 2
    own, next_lane = lane_centre(EGO_LANE), EGO_LANE + 1
    script: LeadBraking | LaneMove
    if point.kind == "lead-braking":
        actors = [Actor(ego_front + p["time_gap"] * speed + LENGTH / 2, own, speed)]
        script = LeadBraking(p["deceleration"])
    elif point.kind == "cut-in":
        cutter_speed = max(speed - p["relative_speed"], 0.0)
        start = ego_front + p["gap"] + (speed - cutter_speed) * LEAD_IN_S + LENGTH / 2
        actors = [Actor(start, lane_centre(next_lane), cutter_speed)]
        script = LaneMove(0, 0, p["gap"], EGO_LANE, p["lateral_speed"])
    else:
        leader_gap = max(
            min(LEADER_TIME_GAP_S * speed + LEADER_STANDSTILL_M, p["distance"] - LENGTH - 2.0), 2.0
        )
        stationary = ego_front + p["distance"] + speed * LEAD_IN_S + LENGTH / 2
        actors = [Actor(ego_front + leader_gap + LENGTH / 2, own, speed), Actor(stationary, own, 0.0)]
        script = LaneMove(0, 1, p["distance"], next_lane, p["lateral_speed"])
    return ScriptedRoad(lanes, EGO_LANE, speed, actors, script, plant, dt, DURATION_S)
