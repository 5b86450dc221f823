"""One closed-loop episode as a steppable object, shared by `drivestack run` and the gym env.

Each decision point: `grid = loop.perceive()`, the agent picks a command, `loop.act(command)` runs
the control ticks up to the next decision point (one decision period, or until a lane change ends).
Each tick reads like do-mpc's loop: reference from the maneuver, `controller.step(state, reference,
dt)`, `plant.step(actuation)`.
"""

from __future__ import annotations

import numpy as np

from controllers.cruise import AdaptiveCruise
from controllers.maneuver import Maneuver
from controllers.tracker import make_tracker
from controllers.types import EgoState, Leader, Reference
from perception.grid import GridConfig, OccupancyGrid, OccupancyGridBuilder
from perception.neighbours import leaders
from perception.plot import grid_panel
from perception.sensor import SensorModel
from perception.types import WorldState
from planner.command import Command
from planner.safety import SafetyLayer
from stack.core.config import ControllerConfig, RunConfig
from stack.core.metrics import EpisodeRecorder, EpisodeResult
from stack.sim.highway import HighwayAdapter

SNAPSHOT_TIME_S = 10.0
"""Each episode keeps the (world, grid) of its first decision at or after this time [s]."""


def grid_config(config: RunConfig) -> GridConfig:
    return GridConfig(**config.perception.model_dump(exclude={"sensor"}))


def make_controller(config: ControllerConfig, dt: float):
    gains = config.pid
    cruise = AdaptiveCruise(
        config.time_gap_s,
        config.standstill_gap_m,
        config.comfort_decel_mps2,
        gains.kp_speed,
        gains.ki_speed,
        gains.max_acceleration,
    )
    return make_tracker(config.type, gains, config.mpc, cruise, dt)


def lane_curvature(lane, s: float) -> float:
    """Curvature [1/m] of `lane` at `s`: central difference of its heading over +-1 m."""
    return (lane.heading_at(s + 1.0) - lane.heading_at(s - 1.0)) / 2.0


def ego_state(world: WorldState, lane: int) -> EgoState:
    """The ego in the frame of `lane`: lateral offset, heading relative to the lane, speed, and
    the lane's curvature."""
    ego = world.ego
    geometry = world.lanes[lane]
    return EgoState(
        d=ego.d,
        heading=ego.heading - geometry.heading_at(ego.s),
        speed=ego.speed,
        curvature=lane_curvature(geometry, ego.s),
    )


class ClosedLoop:
    """Plant, perception, safety layer, maneuver, controller and metrics of one episode."""

    def __init__(
        self,
        config: RunConfig,
        adapter: HighwayAdapter,
        frames: list[np.ndarray] | None = None,
        grid: GridConfig | None = None,
    ) -> None:
        """`grid` overrides the config's perception grid (an agent that needs its own view)."""
        self.config = config
        self.adapter = adapter
        self.frames = frames
        self.builder = OccupancyGridBuilder(grid or grid_config(config))

    def reset(self, seed: int) -> WorldState:
        config = self.config
        self.seed = seed
        self.world = self.adapter.reset(seed)
        self.sensor = SensorModel(config.perception.sensor, seed)
        self.safety = SafetyLayer(config.planner.safety)
        self.controller = make_controller(config.controller, self.adapter.dt)
        self.maneuver = Maneuver(self.world, config.controller.lane_change_duration_s)
        self.recorder = EpisodeRecorder(self.world)
        self.grid: OccupancyGrid | None = None
        self.snapshot: tuple[WorldState, OccupancyGrid] | None = None
        return self.world

    @property
    def done(self) -> bool:
        return self.adapter.done

    @property
    def crashed(self) -> bool:
        return self.adapter.terminated

    def perceive(self) -> OccupancyGrid:
        """The grid the planner decides on now (through the sensor model)."""
        self.grid = self.builder.build(self.sensor.observe(self.world))
        if self.snapshot is None or self.snapshot[0].time < SNAPSHOT_TIME_S:
            self.snapshot = (self.world, self.grid)
        return self.grid

    def act(self, command: Command) -> int:
        """Apply `command` (through the safety layer) and run control ticks until the next decision
        point or the end of the episode; returns the ticks run."""
        self._start(command)
        ticks = 0
        while not self.done:
            self.tick()
            ticks += 1
            if self.maneuver.update(self.world) or (
                not self.maneuver.changing_lane and ticks >= self.config.decision_ticks
            ):
                break
        return ticks

    def advance(self, command: Command, ticks: int) -> int:
        """Apply `command` unless a lane change is still running (then it is ignored) and run
        exactly `ticks` control ticks, or to the episode end: the fixed-period step of the training
        MDP, so every transition spans the same time and one discount factor fits all."""
        if not self.maneuver.changing_lane:
            self._start(command)
        run = 0
        while run < ticks and not self.done:
            self.tick()
            self.maneuver.update(self.world)
            run += 1
        return run

    def _start(self, command: Command) -> None:
        self.maneuver.command(self.safety.filter(command, self.world, self.maneuver.lane), self.world)

    def tick(self) -> None:

        world, maneuver = self.world, self.maneuver
        if (
            maneuver.changing_lane
            and not maneuver.crossed(world)
            and self.safety.should_abort(world, maneuver.target)
        ):
            maneuver.abort(world)
        d, d_dot, d_ddot = maneuver.reference(world.time)
        dt = self.adapter.dt
        reference = Reference(
            d,
            d_dot,
            d_ddot,
            set_speed=self.config.controller.set_speed_mps,
            leaders=tuple(Leader(*lead) for lead in leaders(world, maneuver.occupied_lanes)),
            preview=tuple(
                maneuver.reference(world.time + k * dt)[:2]
                for k in range(1, self.controller.preview_steps + 1)
            ),
        )
        actuation = self.controller.step(ego_state(world, maneuver.lane), reference, self.adapter.dt)
        self.world = self.adapter.step(actuation)
        self.recorder.record(self.world)
        if self.frames is not None and self.adapter.rendering:
            frame = self.adapter.render()
            self.frames.append(np.vstack([frame, grid_panel(self.grid, frame.shape[1])]))

    def result(self, episode: int) -> EpisodeResult:
        result = self.recorder.result(
            episode,
            self.seed,
            self.crashed,
            self.maneuver.lane_changes,
            self.adapter.dt,
            masked=self.safety.masked,
            aborted=self.safety.aborted,
        )
        result.snapshot = self.snapshot
        return result
