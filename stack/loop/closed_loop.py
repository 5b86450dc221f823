"""One closed-loop episode as a steppable object, shared by `drivestack run`, `track`, the safety
assessment and the decision MDP.

At a decision point: `grid = loop.perceive()`, the agent decides, `loop.act(command)` runs control
ticks up to the next decision point. Each tick reads like do-mpc's loop: the maneuver gives the
reference, the controller the actuation, the plant the next world; it returns a frozen `Tick`,
which the metrics recorder, the safety monitor and the video consume outside the tick. Its face:
`reset`, `perceive`, `act`, `tick`, the `world` (truth), `detected` (what the sensor reports) and
`perceived` (what the layers act on: the tracker's confirmed tracks, `perception.tracking`, or the
detections themselves with the tracker off) snapshots, `done` / `crashed`, `status()`, `traces()`,
`solve_statistics()` and `result()`;
`observation(grid, encoding, with_permitted)`, what an agent decides on (with `permitted()`, the
commands `act` would carry out, for an agent trained with an action mask); for planners that look
ahead, `permits`, `changing_lane` and `fork` (a copy to play the future on); for a scripted
maneuver, `start_lane_change`.
"""

from __future__ import annotations

import copy
import math
from typing import TYPE_CHECKING, Protocol

import numpy as np

from controllers.emergency import EmergencyBraking
from controllers.maneuver import Maneuver
from controllers.protocol import Controller
from controllers.tracker import make_controller
from perception.grid import OccupancyGrid, OccupancyGridBuilder
from perception.sensor import SensorModel
from perception.tracking import Tracker
from planner.safety import SafetyLayer
from records import Actuation, Command, Encoding, GridConfig, WorldState
from stack.fault.emergency_causes import BrakingsByCause, CauseTracker, cause_label
from stack.loop.loop_records import Acted, LoopStatus, SolveStatistics, Tick
from stack.loop.metrics import EpisodeRecorder, Traces
from stack.loop.safety_metrics import SafetyMonitor, monitored
from stack.results.episode_fields import record_fields
from stack.results.episode_measures import measured
from stack.results.episode_result import EpisodeResult
from stack.settings.run import RunConfig, episode_sensor, grid_config

if TYPE_CHECKING:
    from stack.loop.recording import EpisodeRecording
    from stack.loop.video import Video
    from stack.results.tracking_quality import TrackingQuality

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

    def show_intent(self, lane: int) -> None: ...


class ClosedLoop:
    """Plant, perception, safety layer, maneuver, controller and metrics of one episode."""

    def __init__(
        self,
        config: RunConfig,
        plant: Plant,
        frames: list[np.ndarray] | None = None,
        grid: GridConfig | None = None,
        controller: Controller | None = None,
        recording: EpisodeRecording | None = None,
    ) -> None:
        """`grid` overrides the config's perception grid (an agent that needs its own view);
        `frames`, when given, collects a rendered frame every `VIDEO_FRAME_TICKS` ticks;
        `controller` replaces the one the config names (reset at every episode); `recording`,
        when given, records the episode (`stack.loop.recording`; one loop, one episode)."""
        self.config = config
        self.plant = plant
        self.frames = frames
        self.recording = recording
        self.given_controller = controller
        self.builder = OccupancyGridBuilder(grid or grid_config(config))
        self.other_views: dict[str, OccupancyGridBuilder] = {}
        """The builders of `perceive_as`, by grid."""
        self.quality: TrackingQuality | None = None
        """When set, scores every tick's perceived world against the truth (`drivestack tracking`)."""

    def reset(self, seed: int) -> WorldState:
        config = self.config
        self.seed = seed
        self.world = self.plant.reset(seed)
        sensor = episode_sensor(config, seed)
        self.sensor = SensorModel(sensor, seed)
        self.detected = self.perceived = self._observe()
        self.tracker: Tracker | None = None
        if config.perception.tracker.tracks(sensor) and not config.perception.control_on_ground_truth:
            self.tracker = Tracker(config.perception.tracker, sensor)
            warm_up = [self.perceived] + [
                self._observe() for _ in range(config.perception.tracker.confirm_frames - 1)
            ]
            self.perceived = self.tracker.warm_up(warm_up)
        self.safety = SafetyLayer(config.planner.safety)
        self.controller = self.given_controller or make_controller(
            config.controller, self.plant.dt, config.sim.plant
        )
        self.controller.reset()
        self.fallbacks_before = self.controller.fallbacks
        self.solves_before = self.solves_recorded = len(self.controller.solve_times)
        control = config.controller
        self.maneuver = Maneuver(
            self.world,
            control.lane_change_duration_s,
            control.set_speed_mps,
            self.safety.should_abort,
            min_speed=control.min_lane_change_speed_mps,
            max_course=math.radians(control.lane_change_max_course_deg),
            cut_in_lookahead_s=control.cut_in_lookahead_s,
            weaver_wary_s=control.weaver_wary_s,
        )
        self.emergency = EmergencyBraking(
            control.emergency_decel_mps2, control.comfort_decel_mps2, control.emergency_ttc_s
        )
        self.monitor = SafetyMonitor(self.plant.dt)
        self.monitor.start(self.world)
        self.causes = CauseTracker(self.plant.dt)
        self.causes.observe(self.world)
        self.recorder: EpisodeRecorder | None = EpisodeRecorder(self.world)
        self.video: Video | None = None
        if self.frames is not None:
            from stack.loop.video import Video  # PIL and the grid pictures: loaded only for a video

            title = (
                f"{config.planner.agent} + {config.controller.type}, "
                f"{config.scenario or 'configured world'}, seed {seed}"
            )
            self.video = Video(self.frames, self.plant, title, VIDEO_FRAME_TICKS)
        self.command: Command = Command.STAY
        self.applied: Command | None = Command.STAY
        self.fallback_decisions = 0
        self.grid: OccupancyGrid | None = None
        self.gridded: WorldState = self.perceived
        self.snapshot: tuple[WorldState, OccupancyGrid] | None = None
        if self.recording is not None:
            self.recording.start(self.world, self.plant.dt, self.maneuver.lane)
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
            self.gridded = self.sensor.observe(self.world)
        else:
            self.gridded = self.perceived
        self.grid = self.builder.build(self.gridded)
        if self.snapshot is None or self.snapshot[0].time < SNAPSHOT_TIME_S:
            self.snapshot = (self.world, self.grid)
        return self.grid

    def perceive_as(self, grid: GridConfig | None) -> OccupancyGrid:
        """The world `perceive` last gridded, on `grid` (None: the run's): what another agent
        deciding now (a fallback) sees of the same sensor reading."""
        config = grid or grid_config(self.config)
        key = config.model_dump_json()
        if key not in self.other_views:
            self.other_views[key] = OccupancyGridBuilder(config)
        return self.other_views[key].build(self.gridded)

    def hand_over(self, spread: float, threshold: float, fallback: str, command: Command) -> None:
        """The decision about to be acted on went to `fallback`, which chose `command`: the
        ensemble's members disagreed by `spread` above `threshold` [Q-value]."""
        self.fallback_decisions += 1
        if self.recording is not None:
            self.recording.handed_over(self.world.time, spread, threshold, fallback, command)

    def act(self, command: Command, ticks: int | None = None) -> Acted:
        """Apply `command` through the safety layer, unless a lane change is still running (then
        it is ignored), and run control ticks to the next decision point or the episode's end.

        The next decision point is, by default, one decision period later or, once a lane change
        started, its end. With `ticks`, exactly that many ticks: the fixed-period step of the
        training MDP, so every transition spans the same time and one discount factor fits all."""
        considered = not self.maneuver.changing_lane
        self.command, self.applied = command, None
        filtered = None
        if considered:
            filtered = self.applied = self.safety.filter(command, self.perceived, self.maneuver.lane)
            if not self.maneuver.command(self.applied, self.world):
                self.applied = Command.STAY
        recording = self.recording
        if recording is not None:
            reacted = self.safety.reacted_to
            recording.decision(self.world, self.grid, command, filtered, self.applied, reacted)
        speeds: list[float] = []
        while not self.done:
            tick = self.tick()
            if self.recorder is not None:
                self.recorder.record(tick)
                self.monitor.record(tick.world, tick.changing_lane)
            else:
                self.monitor.record_departure(tick.world)
            if self.video is not None:
                self.video.add(tick, self.grid, self.command, self.applied)
            if recording is not None:
                self._record(recording, tick)
            speeds.append(float(tick.world.speed[0]))
            completed = self.maneuver.update(self.world)
            if ticks is not None:
                if len(speeds) >= ticks:
                    break
            elif completed or (not self.maneuver.changing_lane and len(speeds) >= self.config.decision_ticks):
                break
        mean_speed = float(np.mean(speeds)) if speeds else float(self.world.speed[0])
        return Acted(len(speeds), considered, mean_speed)

    def _record(self, recording: EpisodeRecording, tick: Tick) -> None:
        """Hand `tick` to the recording with what the safety layer, emergency braking, the safety
        monitor and the controller did on it."""
        times = self.controller.solve_times
        solve = times[-1] if len(times) > self.solves_recorded else None
        self.solves_recorded = len(times)
        last = self.causes.last
        emergency = (
            self.emergency.cause,
            self.emergency.activations,
            cause_label(last) if last is not None else "",
        )
        recording.tick(tick, self.safety.aborted, self.safety.reacted_to, emergency, self.monitor, solve)
        if self.sensor.config.enabled and not self.config.perception.control_on_ground_truth:
            recording.sensed(self.detected, self.perceived if self.tracker is not None else None)

    def tick(self) -> Tick:
        """One control tick: reference, actuation (emergency braking last), one plant step and what
        the sensor reports of the new world. `act` hands the record to the metrics recorder, the
        safety monitor and the video; a tick run alone is recorded by none of them."""
        reference = self.maneuver.reference(self.perceived)
        state = self.world.ego_state()
        actuation = self.controller.step(state, reference)
        activations = self.emergency.activations
        actuation = self.emergency.apply(actuation, state.speed, reference.leaders, self.plant.dt)
        counted = self.recorder is not None
        if counted:
            self.causes.ego(self.world.time, self.maneuver.changing_lane)
        if counted and self.emergency.activations > activations:
            self.causes.attribute(self.world, self.emergency.cause, self.perceived)
        maneuver = self.maneuver
        self.plant.show_intent(maneuver.target if maneuver.changing_lane else -1)
        self.world = self.plant.step(actuation)
        if counted:
            self.causes.observe(self.world)
        self.detected = self.perceived = self._observe()
        if self.tracker is not None:
            self.perceived = self.tracker.update(self.detected, self.plant.dt)
        if self.quality is not None:
            self.quality.record(self.world, self.perceived)
        return Tick(reference, actuation, self.world, maneuver.lane, maneuver.target)

    @property
    def changing_lane(self) -> bool:
        """A lane change runs: `act` ignores the next command until it ends."""
        return self.maneuver.changing_lane

    def start_lane_change(self, command: Command, at_time: float) -> float | None:
        """Plan the lane change `command` to start at `at_time` [s], past the safety layer and the
        decision points (a scripted maneuver, as `drivestack track` drives): its planned duration
        [s], or None when it is refused: STAY, a target off the road, below the maneuver's minimum
        speed, while another change runs, or a start before now."""
        if not self.maneuver.command(command, self.world, start_time=at_time):
            return None
        return self.maneuver.profile.duration

    def permits(self, command: Command) -> bool:
        """Whether the safety layer would pass `command` now (nothing is counted)."""
        return self.safety.permits(command, self.perceived, self.maneuver.lane)

    def permitted(self) -> np.ndarray:
        """Per `Command`, 1.0 where `act` would carry it out now, else 0.0: STAY always; a lane
        change when no change is running, the safety layer passes it and the maneuver would start
        it (at or above its lane-change speed). What an agent trained with an action mask sees."""
        starts = not self.maneuver.changing_lane and float(self.world.speed[0]) >= self.maneuver.min_speed
        return np.array(
            [command is Command.STAY or (starts and self.permits(command)) for command in Command],
            dtype=np.float32,
        )

    def observation(self, grid: OccupancyGrid, encoding: Encoding, with_permitted: bool) -> np.ndarray:
        """What an agent decides on: `grid` in `encoding`, followed by `permitted()` for one trained
        with an action mask (`with_permitted`; the training MDP's observation too)."""
        encoded = grid.encode(encoding)
        return np.concatenate([encoded, self.permitted()]) if with_permitted else encoded

    def fork(self, view: OccupancyGridBuilder | None = None) -> ClosedLoop:
        """A copy of the loop now, to play a future on (the simulator is deterministic, so the copy
        foresees the other vehicles exactly). It records no video and no metrics, only the road
        departure that ends its episode (`done`): its `status`, `traces` and `result` are refused
        (read them on the loop it came from). What no step changes is shared rather than copied
        (the config, the world snapshots: records, never changed once made; the grid builder,
        stateless). `view` replaces the builder of the copy's grids (a planner whose rollouts
        perceive as another agent does)."""
        memo: dict[int, object] = {id(self.config): self.config, id(self.builder): view or self.builder}
        memo |= {
            id(self.frames): None,
            id(self.video): None,
            id(self.recorder): None,
            id(self.recording): None,
            id(self.quality): None,
        }
        snapshot = self.snapshot[0] if self.snapshot is not None else None
        for world in (self.world, self.detected, self.perceived, snapshot):
            if world is not None:
                memo[id(world)] = world
        return copy.deepcopy(self, memo)

    def _recorded(self) -> EpisodeRecorder:
        if self.recorder is None:
            raise RuntimeError("a fork records no metrics: read them on the loop it came from")
        return self.recorder

    def status(self) -> LoopStatus:
        """The loop so far (see `LoopStatus`)."""
        safety = self.safety.counts
        return LoopStatus(
            crashed=self.crashed,
            speed=float(self.world.speed[0]),
            passed_cars=self._recorded().passed_cars,
            lane_changes=self.maneuver.counts.lane_changes,
            masked=safety.masked,
            aborted=safety.aborted,
        )

    def traces(self) -> Traces:
        """The episode's series so far, tick by tick (see `Traces`)."""
        return self._recorded().traces()

    def solve_statistics(self) -> SolveStatistics:
        """The controller's time per tick and fallbacks this episode (see `SolveStatistics`)."""
        solve_ms = 1e3 * np.array(self.controller.solve_times[self.solves_before :])
        p50, p95 = (float(t) for t in np.percentile(solve_ms, [50, 95])) if solve_ms.size else (0.0, 0.0)
        return SolveStatistics(p50, p95, self.controller.fallbacks - self.fallbacks_before)

    def result(self, episode: int) -> EpisodeResult:
        """The episode's result, as its parts measured it so far: what the recorder and the safety
        monitor measured goes in whole (every field measured from the recorder's samples as it declares,
        `SafetyMeasures`: fields named as the result's)."""
        safety, solves = self.safety.counts, self.solve_statistics()
        return EpisodeResult(
            episode=episode,
            seed=self.seed,
            crashed=self.crashed,
            lane_changes=self.maneuver.counts.lane_changes,
            masked_commands=safety.masked,
            aborted_changes=safety.aborted,
            mpc_fallbacks=solves.fallbacks,
            emergency_brakings=self.emergency.activations,
            **record_fields(BrakingsByCause.of(self.causes.counts)),
            fallback_decisions=self.fallback_decisions,
            solve_ms_p50=solves.p50_ms,
            solve_ms_p95=solves.p95_ms,
            snapshot=self.snapshot,
            **measured(EpisodeResult, self._recorded().samples(self.plant.dt)),
            **record_fields(self.monitor.measured()),
            **monitored(self.monitor.kept, 0),
        )
