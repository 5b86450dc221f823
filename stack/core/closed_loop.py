"""One closed-loop episode as a steppable object, shared by `drivestack run`, `track` and the
decision MDP.

At a decision point: `grid = loop.perceive()`, the agent decides, `loop.act(command)` runs control
ticks up to the next decision point. Each tick reads like do-mpc's loop: the maneuver gives the
reference, the controller the actuation, the plant the next world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from controllers.emergency import EmergencyBraking
from controllers.maneuver import Maneuver
from controllers.protocol import Controller
from controllers.tracker import make_controller
from perception.grid import OccupancyGrid, OccupancyGridBuilder
from perception.sensor import SensorModel
from planner.safety import SafetyLayer
from records import Actuation, Command, GridConfig, WorldState
from stack.core.config import RunConfig, grid_config
from stack.core.metrics import EpisodeRecorder, EpisodeResult
from stack.core.safety_metrics import SafetyMonitor

SNAPSHOT_TIME_S = 10.0
"""Each episode keeps the (world, grid) of its first decision at or after this time [s]."""
VIDEO_FRAME_TICKS = 2
"""Control ticks per video frame: the 1st, 3rd, 5th ... tick is drawn (7.5 frames/s at 15 Hz)."""


class Plant(Protocol):
    """What the loop drives: a simulator that turns one actuation into the next world snapshot,
    one control tick of `dt` seconds later (`stack.sim`)."""

    dt: float

    @property
    def done(self) -> bool: ...

    @property
    def terminated(self) -> bool: ...

    @property
    def rendering(self) -> bool: ...

    def reset(self, seed: int) -> WorldState: ...

    def step(self, actuation: Actuation) -> WorldState: ...

    def render(self) -> np.ndarray: ...

    def render_scale(self) -> tuple[float, float]: ...


@dataclass(frozen=True)
class Acted:
    """What one `act` did: control ticks run, whether the command was considered (False while a
    lane change was still running), and the ego's mean speed over those ticks [m/s]."""

    ticks: int
    considered: bool
    mean_speed: float


class ClosedLoop:
    """Plant, perception, safety layer, maneuver, controller and metrics of one episode."""

    def __init__(
        self,
        config: RunConfig,
        plant: Plant,
        frames: list[np.ndarray] | None = None,
        grid: GridConfig | None = None,
        controller: Controller | None = None,
    ) -> None:
        """`grid` overrides the config's perception grid (an agent that needs its own view);
        `frames`, when given, collects a rendered frame every `VIDEO_FRAME_TICKS` ticks;
        `controller` replaces the one the config names (reset at every episode)."""
        self.config = config
        self.plant = plant
        self.frames = frames
        self.given_controller = controller
        self.builder = OccupancyGridBuilder(grid or grid_config(config))

    def reset(self, seed: int) -> WorldState:
        config = self.config
        self.seed = seed
        self.world = self.plant.reset(seed)
        self.sensor = SensorModel(config.perception.sensor, seed)
        self.perceived = self._observe()
        self.safety = SafetyLayer(config.planner.safety)
        self.controller = self.given_controller or make_controller(
            config.controller, self.plant.dt, config.sim.plant
        )
        self.controller.reset()
        self.fallbacks_before = self.controller.fallbacks
        self.solves_before = len(self.controller.solve_times)
        control = config.controller
        self.maneuver = Maneuver(
            self.world,
            control.lane_change_duration_s,
            control.set_speed_mps,
            self.safety.should_abort,
            min_speed=control.min_lane_change_speed_mps,
            max_course=math.radians(control.lane_change_max_course_deg),
        )
        self.emergency = EmergencyBraking(
            control.emergency_decel_mps2, control.comfort_decel_mps2, control.emergency_ttc_s
        )
        self.monitor = SafetyMonitor(self.plant.dt)
        self.recorder = EpisodeRecorder(self.world)
        self.command: Command = Command.STAY
        self.applied: Command | None = Command.STAY
        self.grid: OccupancyGrid | None = None
        self.snapshot: tuple[WorldState, OccupancyGrid] | None = None
        return self.world

    @property
    def done(self) -> bool:
        """The plant's episode ended, or the ego left the road (a failure, as highway-env's
        `offroad_terminal`)."""
        return self.plant.done or self.monitor.road_departure

    @property
    def crashed(self) -> bool:
        return self.plant.terminated

    def _observe(self) -> WorldState:
        """What the sensor reports of the world now, for every layer that acts on the world; the
        simulator's truth when control reads ground truth (then only the grid is sensed)."""
        if self.config.perception.control_on_ground_truth:
            return self.world
        return self.sensor.observe(self.world)

    def perceive(self) -> OccupancyGrid:
        """The grid the planner decides on now (through the sensor model)."""
        if self.config.perception.control_on_ground_truth:
            self.grid = self.builder.build(self.sensor.observe(self.world))
        else:
            self.grid = self.builder.build(self.perceived)
        if self.snapshot is None or self.snapshot[0].time < SNAPSHOT_TIME_S:
            self.snapshot = (self.world, self.grid)
        return self.grid

    def act(self, command: Command, ticks: int | None = None) -> Acted:
        """Apply `command` through the safety layer, unless a lane change is still running (then
        it is ignored), and run control ticks to the next decision point or the episode's end.

        The next decision point is, by default, one decision period later or, once a lane change
        started, its end. With `ticks`, exactly that many ticks: the fixed-period step of the
        training MDP, so every transition spans the same time and one discount factor fits all."""
        considered = not self.maneuver.changing_lane
        self.command, self.applied = command, None
        if considered:
            self.applied = self.safety.filter(command, self.perceived, self.maneuver.lane)
            if not self.maneuver.command(self.applied, self.world):
                self.applied = Command.STAY
        run = 0
        while not self.done:
            self.tick()
            run += 1
            completed = self.maneuver.update(self.world)
            if ticks is not None:
                if run >= ticks:
                    break
            elif completed or (not self.maneuver.changing_lane and run >= self.config.decision_ticks):
                break
        mean_speed = float(np.mean(self.recorder.speed[-run:])) if run else float(self.world.speed[0])
        return Acted(run, considered, mean_speed)

    def tick(self) -> None:
        reference = self.maneuver.reference(self.perceived)
        state = self.world.ego_state()
        actuation = self.controller.step(state, reference)
        actuation = self.emergency.apply(actuation, state.speed, reference.leaders, self.plant.dt)
        self.world = self.plant.step(actuation)
        self.perceived = self._observe()
        self.recorder.record(self.world, reference, actuation)
        self.monitor.record(self.world, self.maneuver.changing_lane)
        if (
            self.frames is not None
            and self.plant.rendering
            and (len(self.recorder.speed) - 1) % VIDEO_FRAME_TICKS == 0
        ):
            self.frames.append(self.frame())

    def frame(self) -> np.ndarray:
        """This tick's video frame: caption, road view, and the grid on the road's scale."""
        from stack.core.video import command_text, video_frame  # matplotlib: loaded only for a video

        assert self.grid is not None, "frames are drawn after the first perceive()"
        config, world, maneuver = self.config, self.world, self.maneuver
        lane = f"lane {maneuver.lane}" + (f" -> {maneuver.target}" if maneuver.changing_lane else "")
        lines = [
            f"{config.planner.agent} + {config.controller.type}, {config.scenario or 'configured world'}, "
            f"seed {self.seed}",
            f"t = {world.time:5.1f} s   v = {world.speed[0]:5.2f} m/s   {lane}   "
            + command_text(self.command, self.applied),
        ]
        road = self.plant.render()
        return video_frame(road, self.grid, self.plant.render_scale(), world.lane_width, lines)

    def status(self) -> dict[str, float | int | bool]:
        """Counters so far: crashed, ego speed [m/s], passed cars, lane changes, masked and aborted
        commands."""
        return {
            "crashed": self.crashed,
            "speed": float(self.world.speed[0]),
            "passed_cars": len(self.recorder.passed),
            "lane_changes": self.maneuver.lane_changes,
            "masked": self.safety.masked,
            "aborted": self.safety.aborted,
        }

    def result(self, episode: int) -> EpisodeResult:
        result = self.recorder.result(
            episode,
            self.seed,
            self.crashed,
            self.maneuver.lane_changes,
            self.plant.dt,
            masked=self.safety.masked,
            aborted=self.safety.aborted,
        )
        monitor = self.monitor
        result.road_departure = monitor.road_departure
        result.collision_kind = monitor.collision.kind if monitor.collision else ""
        result.at_fault_collision = monitor.collision is not None and monitor.collision.at_fault
        result.min_ttc_s = monitor.min_ttc_s
        result.time_below_min_distance_s = monitor.time_below_min_distance_s
        result.emergency_brakings = self.emergency.activations
        result.snapshot = self.snapshot
        result.mpc_fallbacks = self.controller.fallbacks - self.fallbacks_before
        solve_ms = 1e3 * np.array(self.controller.solve_times[self.solves_before :])
        if solve_ms.size:
            result.solve_ms_p50, result.solve_ms_p95 = (float(t) for t in np.percentile(solve_ms, [50, 95]))
        return result
