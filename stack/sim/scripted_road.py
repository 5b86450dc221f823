"""A straight highway-env road with an ego and scripted vehicles: the plant of `drivestack safety`.

The ego is highway-env's kinematic bicycle (`Vehicle`) or its dynamic bicycle (`StableBicycleVehicle`)
on ContinuousAction's terms (acceleration clipped to +-5 m/s^2), driven by whatever the loop
gives it. The other vehicles follow a script (`Actor`): constant speed, a braking phase to
standstill, a lateral move at constant lateral speed, each started by the scenario
(`stack.sim.safety_scenarios`). Only the ego's collisions are checked (highway-env's polygon test);
one ends the episode, like highway-env's crash termination.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, cast

import numpy as np
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle

from records import Actuation, PlantName, WorldState
from stack.sim.highway import MAX_ACCELERATION, snapshot
from stack.sim.plant import StableBicycleVehicle

LANE_WIDTH = 4.0
"""[m] (highway-env's default)."""
EGO_START_S = 200.0
"""Where the ego starts along the road [m]."""
ROAD_LENGTH_M = 20000.0
"""[m]: enough for 130 km/h for longer than any scenario lasts."""


@dataclass
class Actor:
    """A scripted vehicle in the frame of lane 0: `s` (centre, along the road) and `d` (lateral)
    [m], speed [m/s]; it brakes at `braking` [m/s^2] to standstill and moves laterally towards
    `target_d` at `lateral_speed` [m/s] once the scenario sets them."""

    s: float
    d: float
    speed: float
    braking: float = 0.0
    lateral_speed: float = 0.0
    target_d: float | None = None
    vehicle: Vehicle | None = field(default=None, repr=False)

    @property
    def lateral_velocity(self) -> float:
        """The lateral speed it moves at now [m/s], signed (0 once at its target)."""
        if self.target_d is None or self.target_d == self.d:
            return 0.0
        return math.copysign(self.lateral_speed, self.target_d - self.d)

    def advance(self, dt: float) -> None:
        """One tick of `dt` [s], integrated like highway-env's vehicles (position, then speed)."""
        lateral = self.lateral_velocity
        self.s += self.speed * dt
        if self.target_d is not None and lateral:
            step = lateral * dt
            self.d = self.target_d if abs(self.target_d - self.d) <= abs(step) else self.d + step
        self.speed = max(self.speed - self.braking * dt, 0.0)


class Script(Protocol):
    """What starts the actors' moves: called after every tick with the time [s], the ego's centre
    `s` [m] and the actors."""

    def update(self, time: float, ego_s: float, actors: list[Actor]) -> None: ...

    def settled(self, actors: list[Actor]) -> bool: ...


class ScriptedRoad:
    """The plant: `reset` puts the ego on lane `ego_lane`'s centre at `speed` [m/s] with the
    script's actors, `step` applies one actuation for `dt` seconds, moves the actors and checks the
    ego's collisions. The episode ends on a collision, at `duration` [s], or once the script has
    played out and the ego closes in on nobody ahead of it (`resolved`)."""

    rendering = False

    def __init__(
        self,
        lanes: int,
        ego_lane: int,
        speed: float,
        actors: list[Actor],
        script: Script,
        plant: PlantName,
        dt: float,
        duration: float,
    ) -> None:
        self.lanes, self.ego_lane, self.speed, self.plant = lanes, ego_lane, speed, plant
        self.initial = [Actor(a.s, a.d, a.speed, a.braking, a.lateral_speed, a.target_d) for a in actors]
        self.script, self.dt, self.duration = script, dt, duration
        self.view: object | None = None

    def reset(self, seed: int = 0) -> WorldState:
        """The scenario's start (`seed` is unused: a scenario is deterministic)."""
        self.road = Road(network=RoadNetwork.straight_road_network(self.lanes, length=ROAD_LENGTH_M))
        lane = self.road.network.get_lane(("0", "1", self.ego_lane))
        position = lane.position(EGO_START_S, 0.0)
        kind = StableBicycleVehicle if self.plant == "dynamic" else Vehicle
        self.vehicle: Vehicle = kind(self.road, position, 0.0, self.speed)
        self.road.vehicles.append(self.vehicle)
        self.actors = [Actor(a.s, a.d, a.speed, a.braking, a.lateral_speed, a.target_d) for a in self.initial]
        for actor in self.actors:
            actor.vehicle = Vehicle(self.road, np.array([actor.s, actor.d]), 0.0, actor.speed)
            self.road.vehicles.append(actor.vehicle)
        self.ticks = 0
        self.crashed = False
        self.calm_ticks = 0
        self.min_gap_m = math.inf
        self.script.update(0.0, EGO_START_S, self.actors)
        return self.snapshot()

    @property
    def ego_s(self) -> float:
        return float(self.vehicle.position[0])

    @property
    def terminated(self) -> bool:
        """The ego collided."""
        return self.crashed

    @property
    def done(self) -> bool:
        return self.crashed or self.ticks * self.dt >= self.duration or self.calm_ticks * self.dt >= 1.0

    def step(self, actuation: Actuation) -> WorldState:
        acceleration = float(np.clip(actuation.acceleration, -MAX_ACCELERATION, MAX_ACCELERATION))
        Vehicle.act(self.vehicle, {"acceleration": acceleration, "steering": actuation.steering})
        self.vehicle.step(self.dt)
        for actor in self.actors:
            actor.advance(self.dt)
        self.ticks += 1
        self.script.update(self.ticks * self.dt, self.ego_s, self.actors)
        self._place_actors()
        for actor in self.actors:
            self.vehicle.handle_collisions(cast(Vehicle, actor.vehicle), 0.0)
        self.crashed = self.crashed or bool(self.vehicle.crashed)
        self._measure()
        return self.snapshot()

    def _place_actors(self) -> None:
        for actor in self.actors:
            vehicle = cast(Vehicle, actor.vehicle)
            vehicle.position = np.array([actor.s, actor.d])
            vehicle.heading = math.atan2(actor.lateral_velocity, max(actor.speed, 1e-3))
            vehicle.speed = actor.speed
            vehicle.on_state_update()

    def ahead(self) -> list[tuple[float, Actor]]:
        """(bumper gap [m], actor) of every actor ahead whose footprint overlaps the ego's sideways."""
        ego_d = float(self.vehicle.position[1])
        found = []
        for actor in self.actors:
            overlap = abs(actor.d - ego_d) < Vehicle.WIDTH
            if overlap and actor.s > self.ego_s:
                found.append((actor.s - self.ego_s - Vehicle.LENGTH, actor))
        return found

    def _measure(self) -> None:
        """Keep the smallest gap [m] to an actor ahead in the ego's path; count the ticks the
        script has played out with the ego closing in on nobody ahead (`done` after 1 s)."""
        ahead = self.ahead()
        if ahead:
            self.min_gap_m = min(self.min_gap_m, min(gap for gap, _ in ahead))
        closing = any(self.vehicle.speed > actor.speed + 1e-3 for _, actor in ahead)
        calm = self.script.settled(self.actors) and not closing
        self.calm_ticks = self.calm_ticks + 1 if calm else 0

    def snapshot(self) -> WorldState:
        return snapshot(self.road, self.vehicle, self.ticks * self.dt, self.lanes)

    def render(self) -> np.ndarray:
        """highway-env's road view of this road, centred on the ego (`stack.sim.scripted_view`)."""
        from stack.sim.scripted_view import RoadView

        if self.view is None:
            self.view = RoadView()
        return cast(RoadView, self.view).render(self.road, self.vehicle)

    def render_scale(self) -> tuple[float, float]:
        from stack.sim.scripted_view import RoadView

        return RoadView.scale()

    def show_intent(self, lane: int) -> None:
        """Scripted traffic does not read the ego's intent."""
