"""The state of record of a batch of traffic worlds: [worlds, vehicles] arrays, per-world lanes (a
world is read from the road highway-env spawns at reset, `stack.sim.batch.world_reading`), and the
batched layers' view of it (`BatchArrays.world_batch`, a `records.WorldBatch`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from highway_env.road.road import RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle

from common.compiled import Kernel
from records.batch import WorldBatch
from stack.sim.traffic import TrafficVehicle
from stack.sim.vector.habits import SeenPast
from stack.sim.vector.lanes import LaneTable

PLAIN, IDM, TRAFFIC = 0, 1, 2
"""Vehicle kinds: highway-env's kinematic `Vehicle` (the ego, a stopped car), its `IDMVehicle`, the
stack's `TrafficVehicle` (an IDM vehicle that stops at a standstill)."""
KINDS: dict[type, int] = {Vehicle: PLAIN, IDMVehicle: IDM, TrafficVehicle: TRAFFIC}
CLASSES = {kind: cls for cls, kind in KINDS.items()}

DRIVER_LAWS: dict[str, str] = {
    "delta": "DELTA",
    "distance_wanted": "DISTANCE_WANTED",
    "time_wanted": "TIME_WANTED",
    "comfort_acc_max": "COMFORT_ACC_MAX",
    "comfort_acc_min": "COMFORT_ACC_MIN",
    "politeness": "POLITENESS",
    "min_gain": "LANE_CHANGE_MIN_ACC_GAIN",
    "max_braking_imposed": "LANE_CHANGE_MAX_BRAKING_IMPOSED",
    "lane_change_delay": "LANE_CHANGE_DELAY",
}
"""The driver's columns (in `DriverLaws.of`'s order) and the `IDMVehicle` attribute each holds: the
class's, or the driver's own (`stack.sim.drivers`)."""

HABITS: dict[str, str] = {
    "delay_frames": "delay_frames",
    "sudden_braking_chance": "sudden_braking_chance",
    "sudden_braking_frames": "sudden_braking_frames",
    "sudden_braking_mps2": "sudden_braking_mps2",
    "habit_key": "key",
    "blind_to_ego": "blind_to_ego",
    "yields_to_ego": "yields_to_ego",
}
"""The driver's habit columns and the `DriverHabits` field each holds."""

VEHICLE_COLUMNS: dict[str, tuple[type, float]] = {
    "x": (float, 0.0),
    "y": (float, 0.0),
    "heading": (float, 0.0),
    "speed": (float, 0.0),
    "target_speed": (float, 0.0),
    "length": (float, 1.0),
    "width": (float, 1.0),
    "diagonal": (float, 1.0),
    "delta": (float, IDMVehicle.DELTA),
    "distance_wanted": (float, IDMVehicle.DISTANCE_WANTED),
    "time_wanted": (float, IDMVehicle.TIME_WANTED),
    "comfort_acc_max": (float, IDMVehicle.COMFORT_ACC_MAX),
    "comfort_acc_min": (float, IDMVehicle.COMFORT_ACC_MIN),
    "politeness": (float, IDMVehicle.POLITENESS),
    "min_gain": (float, IDMVehicle.LANE_CHANGE_MIN_ACC_GAIN),
    "max_braking_imposed": (float, IDMVehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED),
    "lane_change_delay": (float, IDMVehicle.LANE_CHANGE_DELAY),
    "max_speed": (float, Vehicle.MAX_SPEED),
    "min_speed": (float, Vehicle.MIN_SPEED),
    "timer": (float, 0.0),
    "steering": (float, 0.0),
    "acceleration": (float, 0.0),
    "impact_x": (float, 0.0),
    "impact_y": (float, 0.0),
    "lane": (int, 0),
    "target_lane": (int, 0),
    "kind": (int, PLAIN),
    "crashed": (bool, False),
    "impacted": (bool, False),
    "enable_lane_change": (bool, False),
    "delay_frames": (int, 0),
    "sudden_braking_chance": (float, 0.0),
    "sudden_braking_frames": (int, 0),
    "sudden_braking_mps2": (float, 0.0),
    "habit_key": (int, 0),
    "blind_to_ego": (bool, False),
    "yields_to_ego": (bool, False),
}
"""Every vehicle's columns, (worlds, vehicles) each, with the value of an empty row: its centre (x,
y) [m], heading [rad], speed and IDM target speed [m/s] (0 for a plain vehicle, as IDM reads it),
length, width, diagonal [m], the driver's IDM and MOBIL parameters (exponent, jam distance [m],
time gap [s], a and -b [m/s^2], politeness, threshold and imposed braking [m/s^2], MOBIL's period
[s]: `DRIVER_LAWS`, highway-env's for a plain vehicle), speed range [m/s], lane-change
timer [s], the action it holds (steering [rad], acceleration [m/s^2], as `Vehicle.action`), the
impact to apply at its next step [m], its lane and target lane (rows of its world's lanes; a plain
vehicle's target is its lane), kind,
crash flag, whether an impact is pending, whether MOBIL lane changes are on, and the driver's
habits (`HABITS`: `stack.sim.drivers.DriverHabits`, none for a plain vehicle)."""

LANE_COLUMNS: dict[str, tuple[type, float]] = {
    "lane_length": (float, 0.0),
    "half_width": (float, 0.0),
    "lane_heading": (float, 0.0),
    "speed_limit": (float, np.nan),
    "forbidden": (bool, True),
}
"""Every lane's columns, (worlds, lanes): length, half width [m], heading [rad], speed limit [m/s]
(NaN: none), whether lane changes into it are forbidden."""


ONE_SEGMENT = (np.zeros(1), np.full(1, np.inf))
"""The segments (start, length [m]) of a road whose lanes are one segment: no limit beyond the lanes'."""


class UnsupportedRoad(ValueError):
    """A road the batch cannot hold as arrays."""


@dataclass(frozen=True, eq=False)
class SpawnedWorld:
    """One world as highway-env spawned it: its vehicles' columns (one row each, road order), its
    lanes, the ego's row, and the objects kept for `road_of`."""

    columns: dict[str, np.ndarray]
    lanes: LaneTable
    ego: int
    network: RoadNetwork
    segment_start: np.ndarray = field(default_factory=lambda: ONE_SEGMENT[0])
    """Where each segment of the road the lanes run through starts along them [m] (s, as
    `lane_frames` measures it) and how long it is: highway-env's neighbour search counts a car's
    leaders on its own segment only (`stack.sim.batch.through_road`); one endless segment on a road
    of one segment."""
    segment_length: np.ndarray = field(default_factory=lambda: ONE_SEGMENT[1])


class BatchArrays:
    """The columns of N worlds: `VEHICLE_COLUMNS` (worlds, vehicles) and `LANE_COLUMNS` (worlds,
    lanes) by name (`arrays.x`, `arrays.lane_length`), the lanes' `start` and `lateral` (worlds,
    lanes, 2) and shared `direction` (worlds, 2), each world's lane and vehicle count and ego row.
    A world's vehicles fill its first rows in road order; the arrays grow to the largest world."""

    def __init__(self, worlds: int) -> None:
        self.worlds = worlds
        self.vehicles, self.lanes = 0, 0
        self.columns: dict[str, np.ndarray] = {}
        self.lane_columns: dict[str, np.ndarray] = {}
        self.allocate(1, 1)
        self.count = np.zeros(worlds, dtype=np.int64)
        """Vehicles in each world (its first rows)."""
        self.ego = np.zeros(worlds, dtype=np.int64)
        """The ego's row in each world."""
        self.acts = np.zeros(worlds, dtype=np.int64)
        """Frames each world acted since its reset: the clock of the sudden brakings."""
        self.intent = np.full(worlds, -1, dtype=np.int64)
        """The lane (row) each world's ego shows it is changing into, -1 for none."""
        self.habits = False
        """Whether a world ever loaded holds a driver with habits (`stack.sim.drivers.DriverHabits`)."""
        self.seen: SeenPast | None = None
        """Every row's past s and speed, kept once a loaded world holds a driver with a delay."""
        self.segment_start, self.segment_length = np.zeros((worlds, 1)), np.full((worlds, 1), np.inf)
        """Each world's road segments (W, K) [m] (`SpawnedWorld.segment_start`, `segment_length`)."""
        self.segment_count = np.ones(worlds, dtype=np.int64)
        """How many segments each world's road has."""

    def __getattr__(self, name: str) -> np.ndarray:
        """A vehicle column (worlds, vehicles) or lane column (worlds, lanes) by name (each is also
        set as an attribute, so this runs only for a name that is none)."""
        for table in ("columns", "lane_columns"):
            held = self.__dict__.get(table, {})
            if name in held:
                return held[name]
        raise AttributeError(name)

    def allocate(self, vehicles: int, lanes: int) -> None:
        """Room for `vehicles` a world and `lanes` lanes, keeping what the arrays hold."""
        vehicles, lanes = max(vehicles, self.vehicles), max(lanes, self.lanes)
        if (vehicles, lanes) == (self.vehicles, self.lanes):
            return
        for table, spec, size in (
            (self.columns, VEHICLE_COLUMNS, vehicles),
            (self.lane_columns, LANE_COLUMNS, lanes),
        ):
            for name, (dtype, empty) in spec.items():
                grown: np.ndarray = np.full((self.worlds, size), empty, dtype=dtype)
                old = table.get(name)
                if old is not None:
                    grown[:, : old.shape[1]] = old
                table[name] = grown
        for name, shape in (("start", (lanes, 2)), ("lateral", (lanes, 2))):
            grown = np.zeros((self.worlds, *shape))
            old = self.lane_columns.get(name)
            if old is not None:
                grown[:, : old.shape[1]] = old
            self.lane_columns[name] = grown
        if "direction" not in self.lane_columns:
            self.lane_columns["direction"] = np.zeros((self.worlds, 2))
            self.lane_columns["lane_count"] = np.zeros(self.worlds, dtype=np.int64)
        self.vehicles, self.lanes = vehicles, lanes
        self.flat = {name: column.reshape(-1) for name, column in self.columns.items()}
        """Every vehicle column as one row of all the worlds' vehicles (views: written through)."""
        self.__dict__.update(self.columns)
        self.__dict__.update(self.lane_columns)

    def load(self, world: int, spawned: SpawnedWorld) -> None:
        """Write a spawned world into world `world`'s rows."""
        n, lanes = len(spawned.columns["x"]), len(spawned.lanes.indices)
        self.allocate(n, lanes)
        for name, (_, empty) in VEHICLE_COLUMNS.items():
            self.columns[name][world] = empty
            self.columns[name][world, :n] = spawned.columns[name]
        table = spawned.lanes
        lane_values = {
            "lane_length": table.length,
            "half_width": table.half_width,
            "lane_heading": table.heading,
            "speed_limit": table.speed_limit,
            "forbidden": table.forbidden,
            "start": table.start,
            "lateral": table.lateral,
        }
        for name, values in lane_values.items():
            column = self.lane_columns[name]
            column[world] = LANE_COLUMNS[name][1] if name in LANE_COLUMNS else 0.0
            column[world, :lanes] = values
        self.lane_columns["direction"][world] = table.direction
        self.lane_columns["lane_count"][world] = lanes
        self.count[world], self.ego[world] = n, spawned.ego
        self._load_segments(world, spawned.segment_start, spawned.segment_length)
        self.acts[world], self.intent[world] = 0, -1
        columns = spawned.columns
        self.habits |= any(columns[name].any() for name in HABITS)
        if self.seen is not None or columns["delay_frames"].any():
            self.seen = SeenPast.grown(self.seen, self.worlds, self.vehicles)
            self.seen.pushed[world] = 0

    def _load_segments(self, world: int, start: np.ndarray, length: np.ndarray) -> None:
        more = len(start) - self.segment_start.shape[1]
        if more > 0:
            self.segment_start = np.pad(self.segment_start, ((0, 0), (0, more)))
            self.segment_length = np.pad(self.segment_length, ((0, 0), (0, more)), constant_values=np.inf)
        self.segment_start[world], self.segment_length[world] = 0.0, np.inf
        self.segment_start[world, : len(start)], self.segment_length[world, : len(start)] = start, length
        self.segment_count[world] = len(start)

    @property
    def segmented(self) -> bool:
        """Whether some world's road has more than one segment."""
        return bool((self.segment_count > 1).any())

    def segment_args(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every world's segments: start, length (W, K) [m] and count (W,)."""
        return self.segment_start, self.segment_length, self.segment_count

    def origins(self) -> np.ndarray:
        """Where each world's snapshot measures s and d from (W, 2) [m]: the start of lane 0 of the
        segment its ego is on (`segment_of`), as `stack.sim.highway.snapshot` takes the ego's
        segment's lane 0; lane 0's start on a road of one segment."""
        start, direction = self.lane_columns["start"][:, 0], self.lane_columns["direction"]
        if not self.segmented:
            return start
        worlds = np.arange(self.worlds)
        ego_x, ego_y = self.x[worlds, self.ego], self.y[worlds, self.ego]
        s = (ego_x - start[:, 0]) * direction[:, 0] + (ego_y - start[:, 1]) * direction[:, 1]
        behind = (s[:, None] - self.segment_start > self.segment_length).sum(axis=1)
        segment = np.minimum(behind, self.segment_count - 1)
        return start + self.segment_start[worlds, segment][:, None] * direction

    def lane_args(self) -> tuple[np.ndarray, ...]:
        """Lane count, start, direction and lateral of every world's lanes."""
        lanes = self.lane_columns
        return lanes["lane_count"], lanes["start"], lanes["direction"], lanes["lateral"]

    def world_batch(self) -> WorldBatch:
        """The worlds as the batched layers read them (`records.WorldBatch`): row 0 the ego, then the
        other vehicles in road order, s and d [m] in the frame of lane 0, as `HighwayAdapter`'s
        snapshot computes them (on axis-aligned lanes every product is by 0 or +-1: exact)."""
        lanes = self.lane_columns
        columns = (self.x, self.y, self.speed, self.heading, self.length, self.width, self.lane)
        lane_count, start, direction, lateral = self.lane_args()
        s, d, speed, heading, length, width, lane, offsets = world_rows(
            self.count, self.ego, columns, lane_count, start, direction, lateral, self.origins()
        )
        return WorldBatch(
            count=self.count.copy(),
            s=s,
            d=d,
            speed=speed,
            heading=heading,
            length=length,
            width=width,
            lane=lane,
            lanes_count=lanes["lane_count"].copy(),
            lane_offsets=offsets,
            lane_heading=lanes["lane_heading"][:, 0].copy(),
            lane_width=float(2 * lanes["half_width"][0, 0]),
        )


@Kernel
def world_rows(
    count: np.ndarray,
    ego: np.ndarray,
    columns: tuple[np.ndarray, ...],
    lane_count: np.ndarray,
    start: np.ndarray,
    direction: np.ndarray,
    lateral: np.ndarray,
    origin: np.ndarray,
) -> tuple[np.ndarray, ...]:  # pragma: no cover - compiled
    """`BatchArrays.world_batch`'s rows: per world (`count` vehicles, the ego in row `ego`) its
    vehicles with the ego first, then the others in road order: s and d [m] in lane 0's frame
    from `origin` (W, 2) (`start` (W, L, 2), unit `direction` (W, 2), unit `lateral` (W, L, 2)),
    then each of `columns` (x, y, speed, heading, length, width [floats], lane [ints]) but x and
    y; and each lane's centre offset [m] (W, L). Zeros in the rows and lanes past the counts."""
    x, y, speed, heading, length, width, lane = columns
    worlds, vehicles = x.shape
    s, d = np.zeros((worlds, vehicles)), np.zeros((worlds, vehicles))
    speeds, headings = np.zeros((worlds, vehicles)), np.zeros((worlds, vehicles))
    lengths, widths = np.zeros((worlds, vehicles)), np.zeros((worlds, vehicles))
    lanes = np.zeros((worlds, vehicles), dtype=np.int64)
    offsets = np.zeros((worlds, start.shape[1]))
    for w in range(worlds):
        start_x, start_y = origin[w, 0], origin[w, 1]
        lateral_x, lateral_y = lateral[w, 0, 0], lateral[w, 0, 1]
        for k in range(count[w]):
            i = ego[w] if k == 0 else k - 1 + (1 if k - 1 >= ego[w] else 0)
            delta_x, delta_y = x[w, i] - start_x, y[w, i] - start_y
            s[w, k] = delta_x * direction[w, 0] + delta_y * direction[w, 1]
            d[w, k] = delta_x * lateral_x + delta_y * lateral_y
            speeds[w, k], headings[w, k] = speed[w, i], heading[w, i]
            lengths[w, k], widths[w, k], lanes[w, k] = length[w, i], width[w, i], lane[w, i]
        for j in range(lane_count[w]):
            offsets[w, j] = (start[w, j, 0] - start_x) * lateral_x + (start[w, j, 1] - start_y) * lateral_y
    return s, d, speeds, headings, lengths, widths, lanes, offsets
