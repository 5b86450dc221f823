"""`drivestack track`: single lane changes on an empty highway-env road, one record per maneuver.

For every road (straight; a 1000 m radius bend), plant (highway-env's kinematic bicycle; its
dynamic bicycle with tyre slip, for model mismatch), controller, speed and direction: 1 s of lane
keeping, then a quintic lane change of `duration` seconds from the middle lane's centre to the
neighbour's, then 3 s more. `builtin` is highway-env's own ControlledVehicle lane change.

Metrics (DESIGN.md): lateral RMS / max error to the reference, overshoot past the target centre,
duration (start of lateral motion, |d - d0| > 1 cm, to staying within 0.1 m of the target centre),
peak |a_y| and lateral jerk over a 500 ms moving average (relative to the lane, so a bend's own
v^2 / R is not counted), controller time per tick p50 / p95, MPC fallbacks.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from highway_env.road.lane import CircularLane, LineType
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.dynamics import BicycleVehicle
from highway_env.vehicle.kinematics import Vehicle

from controllers.reference import QuinticProfile
from controllers.types import EgoState, Reference
from stack.core.closed_loop import lane_curvature, make_controller
from stack.core.config import ControllerConfig
from stack.core.metrics import lateral_comfort, moving_average

TRACK_CONTROLLERS = ("pid", "mpc", "builtin")
ROADS = ("straight", "curved")
PLANTS = ("kinematic", "dynamic")
LANE_WIDTH = 4.0
CURVE_RADIUS = 1000.0
"""Radius of lane 0 of the bend [m]."""
LEAD_IN_S = 1.0
SETTLE_S = 3.0


def road_network(kind: str) -> RoadNetwork:
    """Three lanes, straight or a left-hand bend."""
    if kind == "straight":
        return RoadNetwork.straight_road_network(3, length=10000)
    network = RoadNetwork()
    for k in range(3):
        network.add_lane(
            "a",
            "b",
            CircularLane(
                [0.0, 0.0],
                CURVE_RADIUS + LANE_WIDTH * k,
                -np.pi / 2,
                np.pi / 2,
                clockwise=True,
                width=LANE_WIDTH,
                line_types=(LineType.NONE, LineType.NONE),
            ),
        )
    return network


@dataclass
class Maneuver:
    """One lane change; `trace` holds the time series used by the plots."""

    controller: str
    road: str
    plant: str
    speed: float
    direction: str
    duration_s: float | None
    overshoot_m: float
    rms_error_m: float
    max_error_m: float
    peak_lat_accel: float
    peak_lat_jerk: float
    solve_ms_p50: float
    solve_ms_p95: float
    fallbacks: int
    trace: dict | None = None

    def record(self) -> dict:
        return {k: v for k, v in asdict(self).items() if k != "trace"}


def run_maneuver(
    controller_name: str,
    config: ControllerConfig,
    road_kind: str,
    plant: str,
    speed: float,
    direction: str,
    duration: float,
    dt: float,
) -> Maneuver:
    network = road_network(road_kind)
    road = Road(network=network)
    start_node = next(iter(network.graph))
    end_node = next(iter(network.graph[start_node]))
    lanes = network.graph[start_node][end_node]
    origin, target = 1, 0 if direction == "left" else 2
    s0 = 100.0
    position, heading = lanes[origin].position(s0, 0.0), lanes[origin].heading_at(s0)
    if controller_name == "builtin":
        vehicle = ControlledVehicle(
            road,
            position,
            heading,
            speed,
            target_lane_index=(start_node, end_node, origin),
            target_speed=speed,
        )
    else:
        vehicle = (BicycleVehicle if plant == "dynamic" else Vehicle)(road, position, heading, speed)
        controller = make_controller(config.model_copy(update={"type": controller_name}), dt)
    road.vehicles.append(vehicle)
    reference_lane = lanes[0]
    d_origin = reference_lane.local_coordinates(lanes[origin].position(s0, 0.0))[1]
    d_target = reference_lane.local_coordinates(lanes[target].position(s0, 0.0))[1]
    profile = QuinticProfile(d0=d_origin, d1=d_target, t0=LEAD_IN_S, duration=duration)
    steps = round((LEAD_IN_S + duration + SETTLE_S) / dt)
    times, d, d_ref, heading_rel, speeds, steering, tick_ms = [], [], [], [], [], [], []
    for k in range(steps):
        t = k * dt
        s, lateral = reference_lane.local_coordinates(vehicle.position)
        lane_heading = reference_lane.heading_at(s)
        times.append(t)
        d.append(lateral)
        d_ref.append(profile.sample(t)[0])
        heading_rel.append(vehicle.heading - lane_heading)
        speeds.append(vehicle.speed)
        start = time.perf_counter()
        if controller_name == "builtin":
            if abs(t - LEAD_IN_S) < dt / 2:
                vehicle.act("LANE_LEFT" if direction == "left" else "LANE_RIGHT")
            else:
                vehicle.act()
        else:
            curvature = lane_curvature(reference_lane, s)
            value, rate, accel = profile.sample(t)
            reference = Reference(
                value,
                rate,
                accel,
                set_speed=speed,
                preview=tuple(profile.sample(t + j * dt)[:2] for j in range(1, controller.preview_steps + 1)),
            )
            state = EgoState(
                d=lateral, heading=vehicle.heading - lane_heading, speed=vehicle.speed, curvature=curvature
            )
            actuation = controller.step(state, reference, dt)
            vehicle.act({"acceleration": actuation.acceleration, "steering": actuation.steering})
        tick_ms.append((time.perf_counter() - start) * 1e3)
        steering.append(vehicle.action["steering"])
        vehicle.step(dt)
    d, d_ref = np.array(d), np.array(d_ref)
    sign = np.sign(d_target - d_origin)
    moving = np.flatnonzero(np.abs(d - d_origin) > 0.01)
    outside = np.flatnonzero(np.abs(d - d_target) > 0.1)
    duration_s = None
    if moving.size and (not outside.size or outside[-1] < len(d) - 1):
        end = outside[-1] + 1 if outside.size else 0
        duration_s = float(times[end] - times[moving[0]])
    peak_accel, peak_jerk = lateral_comfort(np.array(heading_rel), np.array(speeds), dt)
    error = d - d_ref
    solve = (
        np.array(getattr(controller, "solve_times", [])) * 1e3
        if controller_name == "mpc"
        else np.array(tick_ms)
    )
    window = max(1, round(0.5 / dt))
    lateral_acceleration = moving_average(np.array(speeds)[1:] * np.diff(heading_rel) / dt, window)
    return Maneuver(
        controller=controller_name,
        road=road_kind,
        plant=plant,
        speed=speed,
        direction=direction,
        duration_s=duration_s,
        overshoot_m=float(max(0.0, np.max(sign * (d - d_target)))),
        rms_error_m=float(np.sqrt(np.mean(error**2))),
        max_error_m=float(np.max(np.abs(error))),
        peak_lat_accel=peak_accel,
        peak_lat_jerk=peak_jerk,
        solve_ms_p50=float(np.percentile(solve, 50)),
        solve_ms_p95=float(np.percentile(solve, 95)),
        fallbacks=int(getattr(controller, "fallbacks", 0)) if controller_name != "builtin" else 0,
        trace={
            "time": times,
            "d": (d - d_origin).tolist(),
            "d_ref": (d_ref - d_origin).tolist(),
            "steering": steering,
            "lat_accel": [0.0, *lateral_acceleration.tolist()],
            "lat_jerk": [0.0, 0.0, *moving_average(np.diff(lateral_acceleration) / dt, window).tolist()],
        },
    )


def track(
    controllers: list[str],
    speeds: list[float],
    duration: float,
    config: ControllerConfig,
    out: Path,
    dt: float = 1 / 15,
    roads=ROADS,
    plants=PLANTS,
    progress=None,
) -> list[Maneuver]:
    """All maneuvers; writes out/tracking.json and one figure per speed (straight road, kinematic
    plant, left change, all controllers overlaid)."""
    out.mkdir(parents=True, exist_ok=True)
    maneuvers = []
    for road_kind in roads:
        for plant in plants:
            for name in controllers:
                if name == "builtin" and plant == "dynamic":
                    continue
                for speed in speeds:
                    for direction in ("left", "right"):
                        maneuvers.append(
                            run_maneuver(name, config, road_kind, plant, speed, direction, duration, dt)
                        )
                        if progress:
                            progress()
    (out / "tracking.json").write_text(json.dumps([m.record() for m in maneuvers], indent=2) + "\n")
    for speed in speeds:
        plot_speed(
            [
                m
                for m in maneuvers
                if m.speed == speed
                and m.road == "straight"
                and m.plant == "kinematic"
                and m.direction == "left"
            ],
            out / f"tracking_{speed:g}mps.png",
            speed,
        )
    return maneuvers


def plot_speed(maneuvers: list[Maneuver], path: Path, speed: float) -> None:
    figure, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    for m in maneuvers:
        t = m.trace["time"]
        axes[0].plot(t, m.trace["d"], label=m.controller)
        axes[1].plot(t, np.degrees(m.trace["steering"]))
        axes[2].plot(t, m.trace["lat_accel"])
        axes[3].plot(t, m.trace["lat_jerk"])
    if maneuvers:
        axes[0].plot(maneuvers[0].trace["time"], maneuvers[0].trace["d_ref"], "k--", lw=1, label="reference")
    for axis, label in zip(
        axes,
        ("lateral offset [m]", "steering [deg]", "a_y, 500 ms avg [m/s²]", "jerk, 500 ms avg [m/s³]"),
        strict=True,
    ):
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize="small")
    axes[0].set_title(f"lane change at {speed:g} m/s (straight road, kinematic plant)")
    axes[-1].set_xlabel("time [s]")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)
