"""`Vehicle.step` for many vehicles at once, and the footprints it leaves."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from operator import attrgetter, is_
from typing import Any

import numpy as np
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle

from stack.sim.fast_road import BROAD_PHASE_MARGIN
from stack.sim.traffic import TrafficVehicle
from stack.sim.vector.dynamics import bicycle_step, clipped_actions
from stack.sim.vector.geometry_kernels import SEPARATION_MARGIN, close_pair_rows
from stack.sim.vector.lanes import LaneTable

_KINEMATIC: dict[type, bool] = {}


def steps_like_vehicle(cls: type) -> bool:
    """Whether `cls.step` is highway-env's kinematic `Vehicle.step` (with `IDMVehicle`'s timer, and
    `TrafficVehicle`'s stop at a standstill)."""
    known = _KINEMATIC.get(cls)
    if known is None:
        known = _KINEMATIC[cls] = (
            issubclass(cls, Vehicle)
            and getattr(cls, "step", None) in (Vehicle.step, IDMVehicle.step, TrafficVehicle.step)
            and getattr(cls, "stop_at_standstill", None) in (None, TrafficVehicle.stop_at_standstill)
            and getattr(cls, "clip_actions", None) is Vehicle.clip_actions
            and getattr(cls, "on_state_update", None) is Vehicle.on_state_update
        )
    return known


@dataclass(frozen=True, eq=False)
class FrameActed:
    """What `Road.act()` left for the step that follows it: the movers' speeds [m/s], headings
    [rad] and centres [m] as the act read them (nothing moves a vehicle between the two), and the
    steering [rad] and acceleration [m/s^2] it gave the `driven` rows; the other movers' actions
    are read off them."""

    vehicles: list[Vehicle]
    speed: np.ndarray
    heading: np.ndarray
    position: np.ndarray
    driven: np.ndarray
    steering: np.ndarray
    acceleration: np.ndarray


def move(
    movers: list[Vehicle],
    lanes: LaneTable,
    dt: float,
    record_history: bool,
    acted: FrameActed | None = None,
    constants: np.ndarray | None = None,
) -> Moved:
    """`Vehicle.step(dt)` of every mover: clip, integrate, apply impacts, find the lane. Returns
    where the movers ended. With what the act left (`acted`) and the movers' `MOVER_CONSTANTS` rows
    (`constants`), only their crash state and the undriven movers' actions are read off them."""
    kinds = {cls: _step_kind(cls) for cls in set(map(type, movers))}
    if acted is None or constants is None:
        state = columns(movers, _mover_state)
        speed, max_speed, min_speed, heading, length, width, diagonal = state[:7]
        x, y, steering, acceleration = state[7:11]
        crashed, impacted = state[11] != 0, state[12].nonzero()[0].tolist()
    else:
        speed, heading = acted.speed, acted.heading
        x, y = acted.position.T.copy()
        max_speed, min_speed, length, width, diagonal = constants
        steering, acceleration = _actions(movers, acted)
        crashed = np.fromiter((v.crashed for v in movers), dtype=bool, count=len(movers))
        impacted = [i for i, v in enumerate(movers) if v.impact is not None]
    if len(kinds) == 1:
        stops = np.full(len(movers), next(iter(kinds.values()))[1])
    else:
        stops = np.array([kinds[type(v)][1] for v in movers])
    steering, acceleration = clipped_actions(
        speed, max_speed, min_speed, steering, acceleration, crashed, stops, dt
    )
    heading, speed = bicycle_step(x, y, heading, speed, steering, acceleration, length, dt)
    for i in impacted:
        v = movers[i]
        x[i] += v.impact[0]
        y[i] += v.impact[1]
        v.crashed = True
        v.impact = None
    rows = lanes.closest(x, y, heading).tolist()
    states = zip(
        x.tolist(),
        y.tolist(),
        heading.tolist(),
        speed.tolist(),
        acceleration.tolist(),
        steering.tolist(),
        rows,
        strict=True,
    )
    indices, table = lanes.indices, lanes.lanes
    for v, (x_, y_, h, u, a, steer, row) in zip(movers, states, strict=True):
        action = v.action
        action["steering"], action["acceleration"] = steer, a
        xy = v.position
        xy[0], xy[1] = x_, y_
        v.heading, v.speed = h, u
        v.lane_index, v.lane = indices[row], table[row]
        if record_history:
            v.history.appendleft(v.create_from(v))
    timed = movers if all(timed for timed, _ in kinds.values()) else [v for v in movers if kinds[type(v)][0]]
    for v in timed:
        v.timer += dt
    lane_rows = np.array(rows, dtype=int)
    return Moved(
        movers, Footprints(x, y, heading, speed, length, width, diagonal), lanes.lane_id[lane_rows], lane_rows
    )


@functools.cache
def _step_kind(cls: type) -> tuple[bool, bool]:
    """Whether `cls.step` advances `IDMVehicle`'s lane-change timer, and whether it stops at a
    standstill (`TrafficVehicle`)."""
    step = cls.step  # type: ignore[attr-defined]
    return step in (IDMVehicle.step, TrafficVehicle.step), step is TrafficVehicle.step


def _actions(movers: list[Vehicle], acted: FrameActed) -> tuple[np.ndarray, np.ndarray]:
    """Every mover's (steering, acceleration): the driven rows' from `acted`, the others' read."""
    steering, acceleration = np.empty(len(movers)), np.empty(len(movers))
    steering[acted.driven], acceleration[acted.driven] = acted.steering, acted.acceleration
    undriven = np.ones(len(movers), dtype=bool)
    undriven[acted.driven] = False
    for i in undriven.nonzero()[0].tolist():
        action = movers[i].action
        steering[i], acceleration[i] = action["steering"], action["acceleration"]
    return steering, acceleration


MOVER_CONSTANTS = attrgetter("MAX_SPEED", "MIN_SPEED", "LENGTH", "WIDTH", "diagonal")
"""A mover's MAX_SPEED, MIN_SPEED [m/s], LENGTH, WIDTH and diagonal [m]."""


@dataclass(frozen=True, eq=False)
class KeptColumns:
    """`columns(objects, attributes)` of attributes set when an object is made, kept while the same
    objects, in the same order, ask again."""

    objects: list[Any]
    rows: np.ndarray

    @staticmethod
    def of(objects: list[Any], attributes: Callable[[Any], Any], kept: KeptColumns | None) -> KeptColumns:
        """`kept` if it holds `objects`, else read afresh."""
        if kept is not None and same_objects(kept.objects, objects):
            return kept
        return KeptColumns(list(objects), columns(objects, attributes))


def same_objects(these: Sequence[object], those: Sequence[object]) -> bool:
    """Whether two sequences hold the same objects in the same order."""
    return len(these) == len(those) and all(map(is_, these, those))


def _mover_state(v: Vehicle) -> tuple[float, ...]:
    action, position = v.action, v.position
    return (
        v.speed,
        v.MAX_SPEED,
        v.MIN_SPEED,
        v.heading,
        v.LENGTH,
        v.WIDTH,
        v.diagonal,
        position[0],
        position[1],
        action["steering"],
        action["acceleration"],
        v.crashed,
        v.impact is not None,
    )


_FOOTPRINT = attrgetter("heading", "speed", "LENGTH", "WIDTH", "diagonal")


@dataclass(frozen=True, eq=False)
class Footprints:
    """Vehicles' centres (x, y) [m], headings [rad], speeds [m/s], lengths, widths and diagonals [m]."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    diagonal: np.ndarray

    @staticmethod
    def of(vehicles: list[Vehicle]) -> Footprints:
        """The footprints of `vehicles` as they stand."""
        x, y = np.array([v.position for v in vehicles], dtype=float).T.copy()
        return Footprints(x, y, *columns(vehicles, _FOOTPRINT))


@dataclass(frozen=True, eq=False)
class Moved:
    """Vehicles that a frame moved, and where they ended: their footprints, lane ids (the last item
    of their lane index) and lanes' rows in the road's `LaneTable`."""

    vehicles: list[Vehicle]
    footprints: Footprints
    lane_id: np.ndarray
    lane_row: np.ndarray


def columns(objects: Sequence[object], attributes: Callable[[Any], Any]) -> np.ndarray:
    """The `attributes` of every object, as floats: one contiguous row per attribute (numpy's
    transcendental ufuncs give the bits of their scalar calls on contiguous arrays)."""
    return np.array(list(map(attributes, objects)), dtype=float).reshape(len(objects), -1).T.copy()


def close_pairs(vehicles: Footprints, dt: float) -> np.ndarray:
    """The pairs (i, j), i < j, by i then j, as an (n, 2) array, that pass highway-env's spherical
    pre-check over `dt` [s] (with `BROAD_PHASE_MARGIN`) and whose rectangles, swept by their
    relative displacement over `dt`, are not apart by `SEPARATION_MARGIN` along one of their own
    axes (there stock's separating-axis test finds the same gap: neither impact nor crash): the
    candidates of stock's polygon test, a superset of the pairs it finds touching."""
    return close_pair_rows(
        vehicles.x,
        vehicles.y,
        vehicles.heading,
        vehicles.speed,
        vehicles.length,
        vehicles.width,
        vehicles.diagonal,
        dt,
        BROAD_PHASE_MARGIN,
        SEPARATION_MARGIN,
    )
