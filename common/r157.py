"""UN R157's minimum following distance, and the gap a vehicle is given at spawn on top of it.

d_min = v * t_front(v), paragraph 5.2.3.3's table (1.0 s at 7.2 km/h up to 1.6 s at 60 km/h, linear
in between, 1.6 s above; none below 7.2 km/h). The safety monitor counts the time the ego spends
below it; every start of the stack's roads keeps each vehicle, the ego included, at least this far
behind the one ahead in its lane (`start_gap`), so that no episode begins with a brake."""

from __future__ import annotations

import numpy as np

R157_TIME_GAP = ((7.2, 1.0), (10.0, 1.1), (20.0, 1.2), (30.0, 1.3), (40.0, 1.4), (50.0, 1.5), (60.0, 1.6))
"""UN R157 paragraph 5.2.3.3: (present speed [km/h], minimum time gap t_front [s])."""
R157_MIN_SPEED_MPS = 7.2 / 3.6
"""The table starts at 7.2 km/h [m/s]."""
R157_KMH, R157_GAP = (np.array(column, dtype=float) for column in zip(*R157_TIME_GAP, strict=True))
"""The table's columns: speed [km/h] and t_front [s]."""

START_CLEARANCE_M = 5.0
"""Gap at spawn beyond the rest [m]: highway-env's IDM jam distance, and the margin a follower that
speeds up in its first second (its cruise still reacting) eats into before R157's distance."""
START_REACTION_S = 1.0
"""Time a follower closing in on its leader at spawn drives on before it brakes [s]: the stack
decides once a second and its cruise then reacts."""
START_BRAKING_MPS2 = 3.0
"""Deceleration a follower is given room to brake at from its spawn on [m/s^2]: the stack's comfort
deceleration, so no start needs emergency braking."""
LEADER_BRAKING_MPS2 = 6.0
"""Strongest deceleration of a traffic vehicle [m/s^2] (highway-env's IDM `ACC_MAX`): how hard a
leader spawned above its desired speed may brake towards it from its first frame."""


def r157_min_following_distance(speed: float) -> float:
    """d_min = v * t_front(v) [m] at `speed` [m/s]; 0 below 7.2 km/h, where R157 sets none."""
    return float(r157_min_following_distances(np.float64(speed)))


def r157_min_following_distances(speed: np.ndarray | np.float64) -> np.ndarray:
    """`r157_min_following_distance` of each of `speed` [m/s]."""
    return np.where(speed < R157_MIN_SPEED_MPS, 0.0, speed * np.interp(speed * 3.6, R157_KMH, R157_GAP))


def start_gap(follower_speed: float, leader_speed: float, leader_heading_for: float | None = None) -> float:
    """Least bumper-to-bumper gap [m] behind a leader that a vehicle may spawn at, speeds in m/s:
    `START_CLEARANCE_M` beyond the larger of
    - R157's minimum following distance at its speed, plus, when it is faster than the speed the
      leader is heading for (`leader_heading_for`, default its speed), the road it covers closing
      in for `START_REACTION_S` and braking at `START_BRAKING_MPS2` to that speed;
    - when the leader brakes from its spawn on (heading for a lower speed), the room to stop at
      `START_BRAKING_MPS2` behind it braking to a standstill at `LEADER_BRAKING_MPS2` (what the
      stack's emergency braking predicts of a leader seen braking)."""
    heading_for = leader_speed if leader_heading_for is None else min(leader_heading_for, leader_speed)
    closing = max(follower_speed - heading_for, 0.0)
    following = (
        r157_min_following_distance(follower_speed)
        + closing * START_REACTION_S
        + closing * closing / (2 * START_BRAKING_MPS2)
    )
    stopping = 0.0
    if heading_for < leader_speed:
        stopping = follower_speed**2 / (2 * START_BRAKING_MPS2) - leader_speed**2 / (2 * LEADER_BRAKING_MPS2)
    return START_CLEARANCE_M + max(following, stopping)


def start_room(
    follower_speed: float,
    leader_speed: float,
    follower_length: float,
    leader_length: float,
    leader_heading_for: float | None = None,
) -> float:
    """Least centre-to-centre distance [m] at spawn between a follower and its leader in one lane:
    both half-lengths [m] and `start_gap` at their speeds [m/s]."""
    return (follower_length + leader_length) / 2 + start_gap(follower_speed, leader_speed, leader_heading_for)
