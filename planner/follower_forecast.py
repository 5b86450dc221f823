"""The forecast behind the safety layer's lane-change criterion for the follower (UN R157's: the
approaching vehicle in the target lane not forced to brake harder than 3 m/s^2): how hard the ego
will brake for its leaders during the change (`ego_braking`), whether a follower that reacts
and then brakes at most that hard stays clear of it (`follower_keeps_clear`), and which follower
does not (`unspared_follower`). Plain functions that numba compiles into
`planner.safety.change_is_safe`, for one world or many."""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable

from common.longitudinal import STOP_MARGIN_M
from common.neighbours import VehicleRows, nearest_in_lane

FORECAST_STEP_S = 0.1
"""Time step of the follower's forecast [s]."""
FORECAST_HORIZON_S = 30.0
"""How far the follower's forecast runs at most [s]: past any car's stop from highway speeds."""


@register_jitable
def ego_braking(rows: VehicleRows, centres: tuple[float, float]) -> tuple[float, float]:
    """(deceleration [m/s^2], the speed it brakes to [m/s]) the ego needs to meet, `STOP_MARGIN_M`
    behind, the harder to meet of the nearest vehicles ahead in the lanes centred at `centres` [m]
    at constant speed (0 and its own speed when none closes in)."""
    s, speed, length = rows.s, rows.speed, rows.length
    deceleration, floor = 0.0, speed[0]
    for centre in centres:
        ahead = nearest_in_lane(rows, centre)[0]
        if ahead < 0 or speed[ahead] >= speed[0]:
            continue
        room = max(s[ahead] - s[0] - (length[ahead] + length[0]) / 2 - STOP_MARGIN_M, 0.1)
        needed = (speed[0] - speed[ahead]) ** 2 / (2 * room)
        if needed > deceleration:
            deceleration, floor = needed, speed[ahead]
    return deceleration, floor


@register_jitable
def follower_keeps_clear(
    gap: float,
    follower_speed: float,
    ego_speed: float,
    ego_deceleration: float,
    ego_floor: float,
    braking: float,
    reaction: float,
    keep: float,
) -> bool:
    """Whether a follower `gap` [m] behind the ego (bumper to bumper) at `follower_speed` [m/s]
    stays at least `keep` [m] behind it, holding its speed for `reaction` [s] and then braking at
    most `braking` [m/s^2] (no slower than it needs to follow the ego), while the ego brakes at
    `ego_deceleration` [m/s^2] from `ego_speed` down to `ego_floor` [m/s]. Forecast in steps of
    `FORECAST_STEP_S` until the follower is no faster than the ego and the ego no longer brakes."""
    dt = FORECAST_STEP_S
    for step in range(int(FORECAST_HORIZON_S / dt)):
        t = (step + 1) * dt
        ego_before, follower_before = ego_speed, follower_speed
        ego_speed = max(ego_floor, ego_speed - ego_deceleration * dt)
        if t > reaction:
            follower_speed = max(follower_speed - braking * dt, min(follower_speed, ego_speed))
        gap += (ego_before + ego_speed - follower_before - follower_speed) * dt / 2
        if gap < keep:
            return False
        if t > reaction and follower_speed <= ego_speed and ego_speed <= ego_floor:
            return True
    return True


@register_jitable
def unspared_follower(
    rows: VehicleRows,
    offsets: np.ndarray,
    lane: int,
    goal: int,
    follower_braking_mps2: float,
    follower_reaction_s: float,
    min_gap_m: float,
) -> int:
    """The row of the follower in lane `goal` (-1: none) when, reacting after
    `follower_reaction_s` [s], it would need harder braking than `follower_braking_mps2` [m/s^2]
    to stay `min_gap_m` [m] behind the ego changing into it from `lane`, while the ego brakes as
    its leaders in both lanes ask (`ego_braking`, `follower_keeps_clear`)."""
    behind = nearest_in_lane(rows, offsets[goal])[1]
    if behind < 0:
        return -1
    gap = abs(rows.s[behind] - rows.s[0]) - (rows.length[behind] + rows.length[0]) / 2
    deceleration, floor = ego_braking(rows, (offsets[lane], offsets[goal]))
    spared = follower_keeps_clear(
        gap, rows.speed[behind], rows.speed[0], deceleration, floor,
        follower_braking_mps2, follower_reaction_s, min_gap_m,
    )  # fmt: skip
    return -1 if spared else behind
