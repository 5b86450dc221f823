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
"""Least bumper-to-bumper gap at spawn [m]: highway-env's IDM jam distance beyond both half-lengths."""
START_REACTION_S = 1.0
"""Time a follower closing in on its leader at spawn drives on before it brakes [s]: the stack
decides once a second and its cruise then reacts."""
START_BRAKING_MPS2 = 3.0
"""Deceleration a follower closing in at spawn is given room to slow to its leader's speed at [m/s^2]:
the stack's comfort deceleration, so no start needs emergency braking."""


def r157_min_following_distance(speed: float) -> float:
    """d_min = v * t_front(v) [m] at `speed` [m/s]; 0 below 7.2 km/h, where R157 sets none."""
    if speed < R157_MIN_SPEED_MPS:
        return 0.0
    return speed * float(np.interp(speed * 3.6, R157_KMH, R157_GAP))


def start_gap(follower_speed: float, leader_speed: float) -> float:
    """Least bumper-to-bumper gap [m] behind a leader that a vehicle may spawn at: R157's minimum
    following distance at its speed [m/s] (at least `START_CLEARANCE_M`), plus, when it is faster
    than its leader (`leader_speed`: the speed the leader is heading for, if slower), the road it
    covers closing in for `START_REACTION_S` and then braking at `START_BRAKING_MPS2` to the
    leader's speed."""
    closing = max(follower_speed - leader_speed, 0.0)
    return (
        max(r157_min_following_distance(follower_speed), START_CLEARANCE_M)
        + closing * START_REACTION_S
        + closing * closing / (2 * START_BRAKING_MPS2)
    )


def start_room(
    follower_speed: float, leader_speed: float, follower_length: float, leader_length: float
) -> float:
    """Least centre-to-centre distance [m] at spawn between a follower and its leader in one lane:
    both half-lengths [m] and `start_gap` at their speeds [m/s]."""
    return (follower_length + leader_length) / 2 + start_gap(follower_speed, leader_speed)
