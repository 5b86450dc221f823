"""What a world allows: the mean speed an ego could hold over an episode in each lane, given the
traffic's own speeds, read from the simulator's truth at the episode's start (the benchmark's
progress is measured against the fastest lane's, `stack.apps.benchmark_report`).

A lane's speed is the distance an ego reaches in it over the episode divided by the episode's
length: at most the cruise's set speed (after accelerating to it from the ego's start speed), and
never closer than the cruise's gap behind any vehicle ahead of it in that lane, each taken to drive
at its desired speed (capped by its lane's speed limit and the set speed) for the whole episode,
so a slow truck 100 m ahead holds the lane's speed down to its own plus 100 m, less the gap, over
the episode. It is one reset of the seed's
world (about 10 ms), the same for every agent on that seed, and reads what no deployable agent may
(the drivers' desired speeds): a ceiling of the world, not a forecast. It ignores the time a lane
change takes and the traffic's own lane changes, so a good agent may beat it (progress is capped
at 1) and a world with no better lane gives keep-lane full progress.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from records import WorldState
from stack.settings.run import RunConfig


@dataclass(frozen=True)
class WorldAllowance:
    """The mean speeds [m/s] an ego could hold over the episode: in the fastest lane (`allowed`)
    and in the lane it starts in (`own_lane`, what keeping the lane gives at best)."""

    allowed: float
    own_lane: float


@dataclass(frozen=True)
class Cruise:
    """What the ego's cruise allows: `set_speed` [m/s], `acceleration` [m/s^2] up to it, and the
    gap it keeps to a leader at speed v: `standstill_gap` [m] + `time_gap` [s] x v."""

    set_speed: float
    acceleration: float
    time_gap: float
    standstill_gap: float

    @classmethod
    def of(cls, config: RunConfig) -> Cruise:
        control = config.controller
        return cls(
            control.set_speed_mps, control.pid.max_acceleration, control.time_gap_s, control.standstill_gap_m
        )


def lane_speeds(
    world: WorldState,
    desired: np.ndarray,
    speed_limits: np.ndarray,
    horizon_s: float,
    cruise: Cruise,
) -> np.ndarray:
    """Per lane of `world` (row 0 the ego), the mean speed [m/s] an ego could hold in it over
    `horizon_s` [s]: `desired` [m/s] per row (the ego's unused), `speed_limits` [m/s] per lane
    (inf for none)."""
    start, set_speed, acceleration = float(world.speed[0]), cruise.set_speed, cruise.acceleration
    gain_s = min(max(set_speed - start, 0.0) / acceleration, horizon_s)
    free = start * gain_s + 0.5 * acceleration * gain_s**2 + set_speed * (horizon_s - gain_s)
    reach = np.full(world.lanes_count, max(free, 0.0))
    ahead = world.s - world.s[0] - 0.5 * (world.length + world.length[0])
    for row in range(1, world.count):
        lane = int(world.lane[row])
        if 0 <= lane < world.lanes_count and world.s[row] > world.s[0]:
            speed = max(min(float(desired[row]), float(speed_limits[lane]), set_speed), 0.0)
            gap = cruise.standstill_gap + cruise.time_gap * speed
            reach[lane] = min(reach[lane], max(float(ahead[row]) + speed * horizon_s - gap, 0.0))
    return reach / horizon_s


def world_allowance(config: RunConfig, seed: int) -> WorldAllowance:
    """The `WorldAllowance` of episode `seed` of `config`'s world, from one reset of its road."""
    from stack.runs.kept import kept_adapter

    adapter = kept_adapter(config)
    world = adapter.reset(seed)
    vehicles = adapter.road_env.road.vehicles
    desired = np.array([getattr(vehicles[i], "target_speed", None) or vehicles[i].speed for i in world.ids])
    limits = np.array([getattr(lane, "speed_limit", None) or np.inf for lane in world.lanes])
    speeds = lane_speeds(world, desired, limits, config.highway.duration, Cruise.of(config))
    return WorldAllowance(float(speeds.max()), float(speeds[world.ego_lane]))


def world_allowances(config: RunConfig, seeds: list[int]) -> list[WorldAllowance]:
    """`world_allowance` of each of `seeds` (one work item of a process pool or a Ray task)."""
    return [world_allowance(config, seed) for seed in seeds]
