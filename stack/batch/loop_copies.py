"""Copies of one per-world closed loop as worlds of a batch: `copy_loop` writes a `ClosedLoop` of the
`vector` backend, as it stands mid-episode, into worlds of a `ClosedLoopBatch`, each then the loop's
future as `ClosedLoop.fork` plays it, bit for bit (the batch steps what the vector backend steps alone,
`stack.batch.closed_loop_batch`): the road's vehicles and lanes, the episode's time, the maneuver, the
lateral PID's and the speed PI's memory, emergency braking's memory of its leaders, the weave
memory, and the end flags.

What a batch world cannot hold refuses the copy (`copy_refusal`): a sensor model or tracker (their
noise streams and tracks are per world), a road the arrays cannot hold, a driver acting on a delayed
view (the past he saw is not read back: `copy_loop` raises `UnsupportedRoad`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from controllers.lateral import LateralPID
from controllers.tracker import PIDTracker
from stack.batch.closed_loop_batch import ClosedLoopBatch, refusal
from stack.loop.closed_loop import ClosedLoop
from stack.sim.highway import HighwayAdapter
from stack.sim.vector.road import VectorRoad


def copy_refusal(loop: ClosedLoop) -> str | None:
    """Why `loop` cannot be copied into a batch (one line), or None."""
    refused = refusal(loop.config)
    if refused is not None:
        return refused
    plant = loop.plant
    if not isinstance(plant, HighwayAdapter) or not isinstance(plant.road_env.road, VectorRoad):
        return "a copied loop runs on the vector backend's road"
    sensed = loop.sensor.config.enabled or loop.tracker is not None
    if sensed or loop.config.perception.control_on_ground_truth:
        return "a copied loop acts on the truth: no sensor model or tracker"
    controller = loop.controller
    if not isinstance(controller, PIDTracker) or not isinstance(controller.lateral, LateralPID):
        return "a copied loop drives the PID tracker"
    return None


def copy_loop(batch: ClosedLoopBatch, worlds: Sequence[int], loop: ClosedLoop) -> None:
    """Worlds `worlds` of `batch` set to `loop` as it stands (`copy_refusal` must be None); the
    batch's other worlds are left as they are, and `loop` is only read. `UnsupportedRoad` (nothing
    written) for a road the arrays cannot hold or a driver acting on a delayed view."""
    plant = loop.plant
    assert isinstance(plant, HighwayAdapter)
    env = plant.road_env
    road = env.road
    assert isinstance(road, VectorRoad)
    batch.traffic.load_worlds(worlds, road, env.vehicle, float(env.time), road.acts)
    batch.loaded()
    maneuver, world = loop.maneuver, loop.world
    profile, clock = maneuver.clock.profile, maneuver.clock
    controller = loop.controller
    assert isinstance(controller, PIDTracker) and isinstance(controller.lateral, LateralPID)
    lateral, speed_pi = controller.lateral.memory, controller.cruise.speed_pid.memory
    emergency = loop.emergency
    slot = {int(vehicle): row for row, vehicle in enumerate(world.ids.tolist())}
    seen = np.zeros(batch.seen.shape[1], dtype=np.int64)
    seen_speed, seen_slowing = np.zeros(seen.shape), np.zeros(seen.shape)
    for vehicle, speed in emergency.speeds.items():
        seen[slot[vehicle]], seen_speed[slot[vehicle]] = 1, speed
    for vehicle, slowing in emergency.slowing.items():
        seen[slot[vehicle]], seen_slowing[slot[vehicle]] = 2, slowing
    cause = 0 if emergency.cause is None else slot[emergency.cause]
    weaves = maneuver.weaves
    moving, weaved_at = np.zeros(seen.shape), np.full(seen.shape, -np.inf)
    for column in np.flatnonzero(weaves.keys >= 0).tolist():
        vehicle = int(weaves.keys[column])
        if vehicle in slot:
            moving[slot[vehicle]], weaved_at[slot[vehicle]] = weaves.moving[column], weaves.weaved_at[column]
    rows = list(worlds)
    batch.lane[rows], batch.target[rows] = maneuver.lane, maneuver.target
    batch.coef[rows] = profile.coefficients
    batch.profile[rows] = (profile.t0, profile.duration, profile.d1, profile.peak_lateral_speed)
    batch.clock[rows] = (clock.anchor, clock.profile_anchor, clock.rate)
    batch.counts[rows] = (maneuver.lane_changes, loop.safety.masked, loop.safety.aborted)
    batch.lateral[rows] = (
        lateral.lateral.integral,
        lateral.lateral.output,
        float(lateral.lateral.has_output),
        lateral.steering,
    )
    batch.speed_pi[rows] = (speed_pi.integral, speed_pi.output, float(speed_pi.has_output))
    batch.seen[rows], batch.seen_speed[rows], batch.seen_slowing[rows] = seen, seen_speed, seen_slowing
    batch.flags[rows] = (int(emergency.active), emergency.activations, cause)
    batch.moving[rows], batch.weaved_at[rows] = moving, weaved_at
    batch.departed[rows] = loop.monitor.road_departure
    batch.crashed[rows] = plant.terminated
    batch.truncated[rows] = plant.truncated
