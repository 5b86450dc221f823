"""One world's highway-env objects as the batch's rows and back: `read_world` reads a spawned road
of one segment (`stack.sim.batch.through_road` a road of several) into the columns
`BatchArrays.load` takes, `road_of` builds the objects again from a world's columns, and
`world_state_of_rows` makes the loop's `WorldState` of a world straight from the rows."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle

from records import Lane, WorldState
from records.batch import WorldBatch
from stack.sim.batch.arrays import (
    CLASSES,
    DRIVER_LAWS,
    HABITS,
    KINDS,
    ONE_SEGMENT,
    PLAIN,
    VEHICLE_COLUMNS,
    SpawnedWorld,
    UnsupportedRoad,
)
from stack.sim.drivers import NO_HABITS, DriverHabits, habits_of
from stack.sim.fast_road import LaneIndex
from stack.sim.highway import kinematic_body_rates
from stack.sim.vector.lanes import LaneTable


def read_world(road: Road, ego: Vehicle) -> SpawnedWorld:
    """The arrays of a highway-env road: parallel axis-aligned straight lanes of one segment, level at
    their start (highway-v0's), no obstacles, and vehicles of the kinds in `KINDS` without routes;
    `UnsupportedRoad` names what is not."""
    lanes = LaneTable.fit(road.network)
    if lanes is None or len({index[:2] for index in lanes.indices}) != 1:
        raise UnsupportedRoad("batched traffic needs one segment of parallel, axis-aligned straight lanes")
    return read_vehicles(road, ego, lanes, road.network, lanes.row.__getitem__, routed=False)


def read_vehicles(
    road: Road,
    ego: Vehicle,
    lanes: LaneTable,
    network: RoadNetwork,
    row_of: Callable[[LaneIndex], int],
    routed: bool,
    segments: tuple[np.ndarray, np.ndarray] = ONE_SEGMENT,
) -> SpawnedWorld:
    """The arrays of `road`'s vehicles on `lanes` (of `network`, kept for `road_of`), each lane
    index of the road read as the row `row_of` gives it; `routed`: whether a lane-keeping vehicle
    may follow a route (one along its lane's continuation, which `lanes` hold as one lane, made of
    `segments`: `SpawnedWorld.segment_start` and `segment_length`)."""
    if road.objects or road.neighbour_vehicles_connected_lanes:
        raise UnsupportedRoad("batched traffic drives roads without objects or connected-lane neighbours")
    rows: list[dict[str, Any]] = []
    for vehicle in road.vehicles:
        kind = KINDS.get(type(vehicle))
        if kind is None:
            raise UnsupportedRoad(f"batched traffic has no {type(vehicle).__name__} (only {list(KINDS)})")
        rows.append(_vehicle_row(vehicle, kind, row_of, routed))
    columns: dict[str, np.ndarray] = {
        name: np.array([row[name] for row in rows], dtype=dtype)
        for name, (dtype, _) in VEHICLE_COLUMNS.items()
    }
    return SpawnedWorld(columns, lanes, road.vehicles.index(ego), network, *segments)


def _vehicle_row(
    vehicle: Vehicle, kind: int, row_of: Callable[[LaneIndex], int], routed: bool
) -> dict[str, Any]:
    action, impact = vehicle.action, vehicle.impact
    row: dict[str, Any] = {
        "x": vehicle.position[0],
        "y": vehicle.position[1],
        "heading": vehicle.heading,
        "speed": vehicle.speed,
        "target_speed": getattr(vehicle, "target_speed", 0),
        "length": vehicle.LENGTH,
        "width": vehicle.WIDTH,
        "diagonal": vehicle.diagonal,
        "max_speed": vehicle.MAX_SPEED,
        "min_speed": vehicle.MIN_SPEED,
        "steering": float(action["steering"]),
        "acceleration": float(action["acceleration"]),
        "impact_x": 0.0 if impact is None else impact[0],
        "impact_y": 0.0 if impact is None else impact[1],
        "lane": row_of(vehicle.lane_index),
        "kind": kind,
        "crashed": vehicle.crashed,
        "impacted": impact is not None,
    }
    if kind == PLAIN:
        default = VEHICLE_COLUMNS
        row |= {name: default[name][1] for name in (*DRIVER_LAWS, *HABITS, "timer", "enable_lane_change")}
        return row | {"target_lane": row["lane"]}
    assert isinstance(vehicle, IDMVehicle)
    if vehicle.route and not (routed and not vehicle.enable_lane_change):
        raise UnsupportedRoad("batched traffic has no vehicles following routes")
    return (
        row
        | {name: getattr(vehicle, attribute) for name, attribute in DRIVER_LAWS.items()}
        | {name: getattr(habits_of(vehicle), field) for name, field in HABITS.items()}
        | {
            "timer": vehicle.timer,
            "target_lane": row_of(vehicle.target_lane_index),
            "enable_lane_change": vehicle.enable_lane_change,
        }
    )


def road_of(
    columns: dict[str, np.ndarray], lanes: LaneTable, network: RoadNetwork, np_random: np.random.Generator
) -> list[Vehicle]:
    """highway-env vehicles on a new `Road` over `network`, in road order, built from one world's
    columns (one row per vehicle): the objects stock would hold at this frame."""
    road = Road(network=network, np_random=np_random)
    for i in range(len(columns["x"])):
        value = {name: column[i].item() for name, column in columns.items()}
        cls = CLASSES[value["kind"]]
        position = [value["x"], value["y"]]
        if value["kind"] == PLAIN:
            vehicle = cls(road, position, value["heading"], value["speed"])
        else:
            vehicle = cls(
                road,
                position,
                value["heading"],
                value["speed"],
                target_lane_index=lanes.indices[value["target_lane"]],
                target_speed=value["target_speed"],
            )
            vehicle.timer = value["timer"]
            for name, attribute in DRIVER_LAWS.items():
                setattr(vehicle, attribute, value[name])
            habits = DriverHabits(**{field: value[name] for name, field in HABITS.items()})
            if habits != NO_HABITS:
                vehicle.habits = habits
            vehicle.enable_lane_change = value["enable_lane_change"]
        vehicle.LENGTH, vehicle.WIDTH, vehicle.diagonal = value["length"], value["width"], value["diagonal"]
        vehicle.lane_index = lanes.indices[value["lane"]]
        vehicle.lane = lanes.lanes[value["lane"]]
        vehicle.crashed = value["crashed"]
        vehicle.action = {"steering": value["steering"], "acceleration": value["acceleration"]}
        vehicle.impact = np.array([value["impact_x"], value["impact_y"]]) if value["impacted"] else None
        road.vehicles.append(vehicle)
    return road.vehicles


def world_state_of_rows(
    batch: WorldBatch,
    world: int,
    x: np.ndarray,
    y: np.ndarray,
    crashed: np.ndarray,
    ego: int,
    steering: float,
    time: float,
    lanes: tuple[Lane, ...],
) -> WorldState:
    """World `world` of the truth `batch` (road order, the ego at its row `ego`), with the traffic's
    positions `x`, `y` [m] and `crashed` flags (worlds x rows), the ego's `steering` [rad] and the
    world's `time` [s], on the road of `lanes`, as `stack.sim.highway.snapshot` writes it from the
    objects: row 0 the ego, then the others in road order, ids their places in the road."""
    n = int(batch.count[world])
    ids = np.array([ego, *range(ego), *range(ego + 1, n)])
    speed, heading = batch.speed[world, :n].copy(), batch.heading[world, :n].copy()
    velocity = np.stack([speed * np.cos(heading), speed * np.sin(heading)], axis=1)
    lateral, yaw_rate = kinematic_body_rates(speed[0], steering, float(batch.length[world, 0]))
    return WorldState(
        time=time,
        ids=ids,
        position=np.stack([x[world, ids], y[world, ids]], axis=1),
        heading=heading,
        speed=speed,
        velocity=velocity,
        lane=batch.lane[world, :n].astype(int),
        length=batch.length[world, :n].copy(),
        width=batch.width[world, :n].copy(),
        s=batch.s[world, :n].copy(),
        d=batch.d[world, :n].copy(),
        crashed=crashed[world, ids].astype(bool),
        lanes=lanes,
        lane_offsets=batch.lane_offsets[world, : int(batch.lanes_count[world])].copy(),
        ego_lateral_speed=lateral,
        ego_yaw_rate=yaw_rate,
    )
