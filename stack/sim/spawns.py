"""Drivable starts: the one rule every start on the stack's roads keeps, whichever backend steps
them (`make_room`): no vehicle, the ego included, starts inside UN R157's minimum following
distance, plus room to slow, of the one ahead in its lane (`common.r157.start_gap`)."""

from __future__ import annotations

import numpy as np
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.road.lane import AbstractLane, StraightLane
from highway_env.vehicle.kinematics import Vehicle

from common.r157 import start_room


def lane_coordinates(lane: AbstractLane, positions: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Each position's longitudinal and lateral coordinate [m] on `lane`, as `lane.local_coordinates`
    gives them (the same bits): on a straight lane along a coordinate axis every product is by 0 or
    +-1, so the sums over the whole array are exact; on any other lane, one call per position."""
    direction = getattr(lane, "direction", None)
    if type(lane) is StraightLane and direction is not None and set(np.abs(direction).tolist()) <= {0.0, 1.0}:
        delta = np.asarray(positions, dtype=float).reshape(-1, 2) - lane.start
        lateral = lane.direction_lateral
        along = delta[:, 0] * direction[0] + delta[:, 1] * direction[1]
        return along, delta[:, 0] * lateral[0] + delta[:, 1] * lateral[1]
    local = np.array([lane.local_coordinates(position) for position in positions], dtype=float).reshape(-1, 2)
    return local[:, 0], local[:, 1]


def heading_for(vehicle: Vehicle) -> float:
    """The speed [m/s] `vehicle` is at or slowing to at spawn: an IDM driver above its target speed
    brakes towards it from the first frame."""
    return min(vehicle.speed, float(getattr(vehicle, "target_speed", vehicle.speed)))


def make_room(env: AbstractEnv, vehicle: Vehicle) -> None:
    """Move `vehicle`, just placed ahead of every other, forward along its lane until the vehicle
    behind it in that lane (the ego or traffic; on this lane's line, whichever road segment it
    was placed on), and the ego when it is behind in a lane next to it (a lane it may change
    into), start at least `start_gap` behind it, bumper to bumper: UN R157's minimum following
    distance at their speed and room to slow to `vehicle`'s. The one rule of every start on the
    stack's roads, whichever backend steps them."""
    lane = env.road.network.get_lane(vehicle.lane_index)
    s_new = lane.local_coordinates(vehicle.position)[0]
    others = [other for other in env.road.vehicles if other is not vehicle]
    if not others:
        return
    positions = [other.position for other in others]
    along, across = lane_coordinates(lane, positions)
    across = np.abs(across)
    width = lane.width_at(s_new)
    behind = along <= s_new
    constraints = []
    in_lane = np.flatnonzero(behind & (across < width / 2))
    if len(in_lane):
        constraints.append(int(in_lane[np.argmax(along[in_lane])]))
    ego_vehicle = env.vehicle
    ego = next((k for k, other in enumerate(others) if other is ego_vehicle), None)
    if ego is not None and behind[ego] and width / 2 <= across[ego] < 1.5 * width:
        constraints.append(ego)
    least = max(
        (
            float(along[k])
            + start_room(
                others[k].speed, vehicle.speed, others[k].LENGTH, vehicle.LENGTH, heading_for(vehicle)
            )
            for k in constraints
        ),
        default=s_new,
    )
    if s_new < least:
        vehicle.position = lane.position(least, 0.0)
