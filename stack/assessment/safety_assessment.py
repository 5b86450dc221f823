"""One point of the safety assessment: the full stack and the reference driver (R157's careful and
competent driver, `stack.fault.reference_driver`) each drive the same scenario on the same plant.

Outcome of a point (the stack's collision vs the reference's):
- `avoided by both`;
- `avoided only by the stack`: the reference collides, the stack does not;
- `failure`: preventable (the reference avoids it) but the stack collides;
- `unpreventable`: both collide.
Besides collisions each drive reports its minimum time to collision [s], minimum gap to a vehicle
ahead in its path [m], peak deceleration [m/s^2] and the time below R157's minimum following
distance [s] (a fourth criterion, not a collision).
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from records import PlantName
from stack.fault.reference_driver import CarefulDriver
from stack.loop.closed_loop import ClosedLoop
from stack.loop.recording import episode_recording
from stack.loop.safety_metrics import SafetyMonitor
from stack.runs.alone import run_agent_episode
from stack.runs.kept import build_agent
from stack.settings.run import RunConfig
from stack.sim.safety_scenarios import Point, build
from stack.sim.scripted_road import ScriptedRoad

OUTCOMES = ("avoided by both", "avoided only by the stack", "failure", "unpreventable")
"""The four outcomes, in the order the maps' colours and the summary list them."""


@dataclass(frozen=True)
class Drive:
    """How one driver did on one point (see the module docstring; units there)."""

    collided: bool
    min_ttc_s: float
    min_gap_m: float
    peak_deceleration: float
    time_below_min_distance_s: float
    emergency_brakings: int = 0


@dataclass(frozen=True)
class Assessed:
    """One point: the stack's drive and the reference driver's."""

    point: Point
    stack: Drive
    reference: Drive

    @property
    def outcome(self) -> str:
        if self.stack.collided:
            return OUTCOMES[3] if self.reference.collided else OUTCOMES[2]
        return OUTCOMES[1] if self.reference.collided else OUTCOMES[0]

    def row(self) -> dict[str, object]:
        """The point's row of safety.csv: scenario, parameters, outcome, then both drives."""
        stack = {f"stack_{k}": _rounded(v) for k, v in asdict(self.stack).items()}
        reference = {f"reference_{k}": _rounded(v) for k, v in asdict(self.reference).items()}
        reference.pop("reference_emergency_brakings")
        return (
            {"scenario": self.point.kind, **self.point.parameters, "outcome": self.outcome}
            | stack
            | reference
        )


def _rounded(value: object) -> object:
    return round(value, 3) if isinstance(value, float) else value


def point_config(config: RunConfig, point: Point) -> RunConfig:
    """`config` with the ego's set speed at the point's speed (it cruises there)."""
    controller = config.controller.model_copy(update={"set_speed_mps": point.parameters["speed"]})
    return config.model_copy(update={"controller": controller})


def plant_for(config: RunConfig, point: Point, plant: PlantName | None = None) -> ScriptedRoad:
    return build(point, config.highway.lanes_count, plant or config.sim.plant, config.dt)


def peak_deceleration(speeds: list[float], dt: float) -> float:
    """Largest drop in speed per second between two ticks [m/s^2] (0 if it never slowed)."""
    if len(speeds) < 2:
        return 0.0
    return float(max(0.0, -np.min(np.diff(speeds)) / dt))


def drive_reference(config: RunConfig, point: Point) -> Drive:
    """The careful and competent driver on `point`, on `config`'s plant."""
    road = plant_for(config, point)
    world = road.reset()
    driver, monitor = CarefulDriver(), SafetyMonitor(road.dt)
    speeds = [float(world.speed[0])]
    while not road.done:
        world = road.step(driver.step(world, road.dt))
        monitor.record(world, False)
        speeds.append(float(world.speed[0]))
    return Drive(
        road.crashed,
        monitor.min_ttc_s,
        road.min_gap_m,
        peak_deceleration(speeds, road.dt),
        monitor.time_below_min_distance_s,
    )


def point_name(point: Point) -> str:
    """A point's recording name (no suffix): its type and parameters, as a file name."""
    return f"{point.kind}-" + re.sub(r"[^A-Za-z0-9_.-]+", "_", point.text.replace("=", "-"))


def drive_stack(
    config: RunConfig, point: Point, frames: list[np.ndarray] | None = None, record: Path | None = None
) -> Drive:
    """The full stack (perception, agent, safety layer, maneuver, controller, emergency braking)
    on `point`; `frames`, when given, collects video frames; with `record` (a folder), the drive is
    recorded there as `point_name(point)`.rrd."""
    config = point_config(config, point)
    road = plant_for(config, point)
    road.rendering = frames is not None
    agent = build_agent(config, config.seed)
    recording = episode_recording(config, record, point_name(point), config.seed)
    loop = ClosedLoop(config, road, frames, grid=agent.grid_config, recording=recording)
    result = run_agent_episode(loop, agent, 0, config.seed)
    if recording is not None:
        recording.close()
    return Drive(
        result.crashed,
        result.min_ttc_s,
        road.min_gap_m,
        peak_deceleration(result.trace["speed"], road.dt),
        result.time_below_min_distance_s,
        result.emergency_brakings,
    )


def assess(task: tuple[RunConfig, Point] | tuple[RunConfig, Point, Path]) -> Assessed:
    """Both drives of one point (a task for `stack.runtime.executors.completed`); with a folder as
    the task's third item, the stack's drive of a failure point is recorded there (every drive is
    recorded, those of the other points deleted once the reference driver's outcome is known)."""
    config, point = task[0], task[1]
    record = task[2] if len(task) > 2 else None
    assessed = Assessed(point, drive_stack(config, point, record=record), drive_reference(config, point))
    if record is not None and assessed.outcome != "failure":
        (record / f"{point_name(point)}.rrd").unlink(missing_ok=True)
    return assessed
