"""Settings of the simulator: the highway-env road and which backend runs it (no highway-env
import here, so configs load fast)."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

from common.r157 import START_BRAKING_MPS2, start_room
from records import BACKENDS, MAX_LANES, PLANTS, ROADS, Backend, PlantName, RoadName, one_of
from stack.worlds.drivers import HIGHWAY_ENV, check_population

MAX_CLASS_BOUND = 60.0
"""Largest desired speed [m/s] and length [m] of a traffic vehicle class (the spawn speed's bound)."""
EGO_SPAWN_SPEED_MPS = 25.0
"""highway-env's ego speed at spawn [m/s] (without `traffic.spawn_speed_mps`)."""
EGO_LENGTH_M = 5.0
"""highway-env's ego length [m] (`Vehicle.LENGTH`)."""
SHARE_TOLERANCE = 1e-6
"""How far the shares of the traffic classes may sum from 1."""


DriverPopulation = str | dict[str, float]
"""A driver population's name (`stack.worlds.drivers.POPULATIONS`), or shares of several by name."""
DRIVERS_HELP = (
    "the traffic's drivers: highway-env (its one IDM/MOBIL parameter set), calibrated, aggressive, "
    "cautious, distracted, blind, mixed, random (one per episode), or shares of several "
    "({calibrated: 0.7, aggressive: 0.3})"
)


def known_population(drivers: DriverPopulation) -> DriverPopulation:
    """`drivers` if it names a population, `random`, or populations whose shares sum to 1
    (`check_population`)."""
    check_population(drivers)
    return drivers


def _ordered_range(bounds: tuple[float, float]) -> tuple[float, float]:
    if not bounds[0] <= bounds[1]:
        raise ValueError(f"must be [low, high] with low <= high, got {list(bounds)}")
    return bounds


class VehicleClass(BaseModel):
    """One kind of traffic vehicle: its share of the traffic, the range its desired (IDM target)
    speed is drawn from [m/s], the range its length is drawn from [m], the lanes it is spawned in
    (None: any) and whether it changes lane (MOBIL) at all; trucks that keep right are
    `lanes: [2, 3], changes_lane: false` on 4 lanes."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    name: str
    share: float = Field(gt=0, le=1)
    speed_mps: tuple[float, float] = Field(description="desired speed range [m/s]")
    length_m: tuple[float, float] = (5.0, 5.0)
    lanes: tuple[int, ...] | None = Field(None, min_length=1, description="spawn lanes (None: any)")
    changes_lane: bool = True

    @field_validator("speed_mps", "length_m")
    @classmethod
    def _positive_and_ordered(cls, bounds: tuple[float, float]) -> tuple[float, float]:
        if not all(0 < bound <= MAX_CLASS_BOUND for bound in bounds):
            raise ValueError(f"must be positive and at most {MAX_CLASS_BOUND:g}, got {list(bounds)}")
        return _ordered_range(bounds)


class IncidentConfig(BaseModel):
    """A stopped vehicle (IDM target speed 0, no lane changes) that blocks `lane`, `ahead_m` metres
    ahead of the ego at spawn; traffic in that lane must stop behind it or merge around it."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    lane: int = Field(ge=0, le=9, description="the blocked lane")
    ahead_m: float = Field(gt=0, le=2000, description="distance ahead of the ego at spawn [m]")
    length_m: float = Field(5.0, gt=0, le=25, description="the stopped vehicle's length [m]")


class TrafficConfig(BaseModel):
    """Heterogeneous traffic (highway-env's IDM / MOBIL vehicles, drawn from the env's seeded
    generator): its drivers (`stack.worlds.drivers`; with no classes, highway-env's own vehicles get
    them), the vehicle classes, where the ego is spawned, as the fraction of the traffic
    spawned behind it (0: behind everybody, highway-env's own placement), and one speed for every
    vehicle at spawn: highway-env spaces vehicles for equal speeds, so a fast car spawned at its
    desired speed just behind a slow truck can rear-end it before IDM has braked."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    classes: tuple[VehicleClass, ...] | None = Field(
        None, min_length=1, description="the vehicle classes (None: highway-env's own vehicles)"
    )
    ego_position: float = Field(0.0, ge=0, le=1, description="fraction of the traffic behind the ego")
    spawn_speed_mps: float | None = Field(
        None,
        gt=0,
        le=60,
        description="every vehicle's speed at spawn [m/s] (None: its desired speed, the ego 25)",
    )
    incident: IncidentConfig | None = None
    drivers: DriverPopulation = Field(HIGHWAY_ENV, description=DRIVERS_HELP)

    @field_validator("drivers")
    @classmethod
    def _known_population(cls, drivers: DriverPopulation) -> DriverPopulation:
        return known_population(drivers)

    @model_validator(mode="after")
    def _placement_needs_classes(self) -> TrafficConfig:
        if self.classes is None and (self.ego_position or self.spawn_speed_mps or self.incident):
            raise ValueError(
                "classes: ego_position, spawn_speed_mps and incident place the classes' vehicles; "
                "give classes, or only drivers for highway-env's own vehicles"
            )
        return self

    @model_validator(mode="after")
    def _incident_leaves_a_drivable_start(self) -> TrafficConfig:
        """A stopped car closer than the ego's start room (`common.r157.start_room`) would make
        the ego brake hard at its first frame: refused, not driven."""
        if self.incident is None:
            return self
        speed = self.spawn_speed_mps or EGO_SPAWN_SPEED_MPS
        room = start_room(speed, 0.0, EGO_LENGTH_M, self.incident.length_m)
        if self.incident.ahead_m < room:
            raise ValueError(
                f"incident.ahead_m: the ego spawns at {speed:g} m/s (traffic.spawn_speed_mps) and needs "
                f"{room:.1f} m to the stopped car (R157's following distance and room to stop at "
                f"{START_BRAKING_MPS2:g} m/s^2), got {self.incident.ahead_m:g}"
            )
        return self

    @field_validator("classes")
    @classmethod
    def _shares_sum_to_one(cls, classes: tuple[VehicleClass, ...] | None) -> tuple[VehicleClass, ...] | None:
        if classes is None:
            return classes
        total = sum(c.share for c in classes)
        if abs(total - 1.0) > SHARE_TOLERANCE:
            raise ValueError(f"the shares must sum to 1, got {total:g}")
        return classes


def _ordered_pair(bounds: tuple[float, float], low: float, high: float) -> tuple[float, float]:
    if not all(low <= bound <= high for bound in bounds):
        raise ValueError(f"must lie in [{low:g}, {high:g}], got {list(bounds)}")
    return _ordered_range(bounds)


RANGE_LIMITS: dict[str, tuple[float, float]] = {
    "vehicles_per_lane": (0.0, 50.0),
    "vehicles_density": (0.1, 10.0),
    "truck_share": (0.0, 1.0),
    "ego_position": (0.0, 1.0),
    "car_speed_mps": (0.0, MAX_CLASS_BOUND / 2),
    "car_spread_mps": (0.0, MAX_CLASS_BOUND / 2),
    "truck_slower_mps": (0.0, MAX_CLASS_BOUND / 2),
    "position_noise_m": (0.0, 5.0),
    "miss_probability": (0.0, 1.0),
    "false_positives": (0.0, 10.0),
}
"""The bounds [low, high] of each `RandomTrafficConfig` range, in its fields' units."""


class RandomTrafficConfig(BaseModel):
    """Traffic drawn anew for every episode from the env's seeded generator (`stack.sim.traffic`), so
    that no single named world is what an agent sees: the lane count, the number of vehicles per
    lane and highway-env's density, a share of slow vehicles (trucks) that change lane like cars
    (with probability `trucks_change_lane`) or else keep to two lanes, the right two or (with
    probability `trucks_keep_left`) the left two, a car speed range `car_spread_mps` wide whose
    lower bound is drawn from `car_speed_mps`, trucks slower than cars by `truck_slower_mps` (not
    below 2 m/s), every vehicle spawned at the trucks' mid speed, the ego's place in the traffic,
    and, with `incident_probability`, a stopped car 150-350 m ahead in a random lane; and the
    sensor the episode is seen through (`position_noise_m`, `miss_probability`, `false_positives`,
    drawn by the closed loop from the episode's seed, in place of `perception.sensor`'s). The
    defaults span 2-6 lanes, density 0.5-3, 0-70 % trucks, desired speeds 2-36 m/s, the ego
    anywhere from the back to the front of the traffic, and a sensor from perfect to the `noisy`
    scenario's (0.5 m, 5 % missed, 0.2 phantoms an observation)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    lanes_count: tuple[int, int] = Field((2, 6), description="lane counts drawn from [low, high]")
    vehicles_per_lane: tuple[float, float] = (8.0, 20.0)
    vehicles_density: tuple[float, float] = (0.5, 3.0)
    truck_share: tuple[float, float] = (0.0, 0.7)
    trucks_change_lane: float = Field(0.3, ge=0, le=1, description="probability that trucks change lane")
    trucks_keep_left: float = Field(
        0.25, ge=0, le=1, description="probability that lane-keeping trucks keep to the two left lanes"
    )
    car_speed_mps: tuple[float, float] = Field(
        (3.0, 28.0), description="the cars' lowest desired speed [m/s]"
    )
    car_spread_mps: tuple[float, float] = Field((3.0, 8.0), description="the cars' speed range [m/s]")
    truck_slower_mps: tuple[float, float] = Field((2.0, 10.0), description="how much slower trucks are [m/s]")
    ego_position: tuple[float, float] = Field((0.0, 1.0), description="the traffic's fraction behind the ego")
    incident_probability: float = Field(0.15, ge=0, le=1)
    position_noise_m: tuple[float, float] = Field((0.0, 0.5), description="the sensor's position noise [m]")
    miss_probability: tuple[float, float] = Field((0.0, 0.05), description="the sensor's missed detections")
    false_positives: tuple[float, float] = Field(
        (0.0, 0.2), description="the sensor's phantom vehicles per observation"
    )
    drivers: DriverPopulation = Field(HIGHWAY_ENV, description=DRIVERS_HELP)

    @field_validator("drivers")
    @classmethod
    def _known_population(cls, drivers: DriverPopulation) -> DriverPopulation:
        return known_population(drivers)

    @field_validator("lanes_count")
    @classmethod
    def _lanes(cls, bounds: tuple[int, int]) -> tuple[int, int]:
        if not 2 <= bounds[0] <= bounds[1] <= MAX_LANES:
            raise ValueError(f"must be [low, high] with 2 <= low <= high <= {MAX_LANES}, got {list(bounds)}")
        return bounds

    @field_validator(*RANGE_LIMITS)
    @classmethod
    def _within_limits(cls, bounds: tuple[float, float], info: ValidationInfo) -> tuple[float, float]:
        return _ordered_pair(bounds, *RANGE_LIMITS[info.field_name or ""])


class HighwayConfig(BaseModel):
    """The section handed to highway-env (`gym.make("highway-v0" or "exit-v0", config=...)`):
    which `road`, highway-env's own keys, and `traffic` (heterogeneous traffic, `stack.sim.traffic`,
    on the straight highway only; exit-v0 spawns its own lane-keeping traffic)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)

    road: Annotated[RoadName, one_of("road", ROADS)] = "highway"
    lanes_count: int = Field(4, ge=1, le=MAX_LANES)
    vehicles_count: int = Field(50, ge=0, le=500)
    vehicles_density: float = Field(1.0, gt=0, le=10)
    duration: float = Field(40.0, gt=0, le=3600, description="episode length [s]")
    simulation_frequency: int = Field(15, ge=1, le=1000, description="physics rate [Hz]")
    ego_spacing: float = Field(2.0, gt=0, le=20, description="ratio of the ego's spawn gap to the default")
    initial_lane_id: int | None = Field(None, ge=0, le=9, description="the ego's spawn lane (None: random)")
    traffic: TrafficConfig | None = None
    random_traffic: RandomTrafficConfig | None = Field(
        None, description="traffic (and lane count) drawn for every episode; replaces traffic"
    )

    @property
    def lane_counts(self) -> tuple[int, ...]:
        """Every lane count an episode of this road can have."""
        if self.random_traffic is None:
            return (self.lanes_count,)
        low, high = self.random_traffic.lanes_count
        return tuple(range(low, high + 1))

    @model_validator(mode="after")
    def _keys_the_road_uses(self) -> HighwayConfig:
        if self.road == "exit" and (self.traffic is not None or self.random_traffic is not None):
            raise ValueError(
                "traffic: the exit road spawns its own traffic; vehicle classes need road: highway"
            )
        if self.random_traffic is not None and (self.traffic is not None or self.initial_lane_id is not None):
            raise ValueError(
                "random_traffic: draws the traffic and the ego's lane; remove traffic and initial_lane_id"
            )
        if self.road == "exit" and self.initial_lane_id is not None:
            raise ValueError("initial_lane_id: the exit road always starts the ego in lane 0")
        return self

    @model_validator(mode="after")
    def _lane_on_road(self) -> HighwayConfig:
        if self.initial_lane_id is not None and self.initial_lane_id >= self.lanes_count:
            raise ValueError(
                f"initial_lane_id: must be a lane of the road (0..{self.lanes_count - 1}), "
                f"got {self.initial_lane_id}"
            )
        incident = self.traffic.incident if self.traffic else None
        if incident is not None and incident.lane >= self.lanes_count:
            raise ValueError(
                f"traffic.incident.lane: must be a lane of the road (0..{self.lanes_count - 1}), "
                f"got {incident.lane}"
            )
        for vehicle_class in (self.traffic.classes or ()) if self.traffic else ():
            if any(not 0 <= lane < self.lanes_count for lane in vehicle_class.lanes or ()):
                raise ValueError(
                    f"traffic.classes.lanes: class {vehicle_class.name!r} must spawn on lanes of the "
                    f"road (0..{self.lanes_count - 1}), got {list(vehicle_class.lanes or ())}"
                )
        return self


class SimConfig(BaseModel):
    """How the physics runs: the backend (`vector`, `fast` or `stock`: identical trajectories) and
    the ego's plant (`kinematic` bicycle, or `dynamic`: highway-env's `BicycleVehicle` with linear
    tyres, the controllers' model mismatch)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    backend: Annotated[Backend, one_of("backend", BACKENDS)] = "vector"
    plant: Annotated[PlantName, one_of("plant", PLANTS)] = "kinematic"
    batched: bool = Field(
        True,
        description="run and compare step their episodes together as batches of worlds where the "
        "config allows (the same results; false: one world at a time)",
    )
