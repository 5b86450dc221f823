"""An episode as a rerun recording (`.rrd`): what `--record` writes, one file per episode (docs/recording.md
lists every entity path and its unit).

The loop hands the recording what it does outside the tick, as it does the video: `start` at reset,
`decision` at each decision point (with the agent's `scores`, when it has them), `tick` after each
control tick. Each tick is kept as a few numbers and the vehicles' box corners; `close` writes them
all at once as columns (`stack.rrd.recording_file`), so recording costs the episode little and
never changes it: it reads the loop's records and counters, it sets nothing.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from common.neighbours import neighbours
from perception.grid import OccupancyGrid
from records import Command, WorldState
from stack.loop.loop_records import Tick
from stack.loop.safety_metrics import SafetyMonitor, r157_min_following_distance
from stack.results.episode_result import TTC_CAP_S
from stack.rrd.recording_file import Buffers, Decision, Frame, write_recording
from stack.rrd.recording_geometry import lane_points
from stack.settings.run import RunConfig

RECORDINGS = "recordings"
"""The results folder's subfolder that holds the recordings."""
REFERENCE_HORIZON_S = 6.0
"""How far ahead the ego's reference path is drawn at each decision and maneuver change [s]."""
REFERENCE_STEP_S = 0.25
"""Spacing of the reference path's points [s]."""


def agent_folders(agents: Sequence[str]) -> dict[str, str]:
    """The subfolder of `RECORDINGS` that holds each agent's episodes in a comparison of `agents`:
    its name as the tables show it (a plug-in by its class name), reduced to a safe file name."""
    from common.plugins import short_labels

    shown = short_labels(list(agents))
    return {
        agent: re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "agent"
        for agent, name in zip(agents, shown, strict=True)
    }


class EpisodeRecording:
    """One episode's recording, written to `path` on `close` (the file appears whole)."""

    def __init__(self, path: Path, title: str) -> None:
        """`title` says what runs (agent, controller, world, seed): the recording's description."""
        self.path, self.title = path, title
        self.buffers = Buffers()
        self.first: WorldState | None = None
        self.dt = 0.0
        self.ticks = 0
        self.pending_scores: tuple[np.ndarray, str] | None = None
        self.safety_reacted: tuple[int, ...] = ()
        self.last_aborted = 0
        self.last_activations = 0
        self.last_min_ttc = TTC_CAP_S
        self.min_ttc_time: float | None = None
        self.below = False
        self.collided = False
        self.departed = False
        self.phase = ""
        self.draw_path = True

    def start(self, world: WorldState, dt: float, lane: int) -> None:
        """The episode begins in `world`; ticks are `dt` seconds apart; the ego keeps `lane`."""
        self.first, self.dt = world, dt
        self.buffers.first = world
        self._world(world, ())
        self._phase(world.time, f"keep lane {lane}")

    def scores(self, values: np.ndarray, name: str) -> None:
        """The agent's scores for the decision about to be made, one per `Command`, in `name`'s unit."""
        self.pending_scores = (np.asarray(values, dtype=float).reshape(-1), name)

    def decision(
        self,
        world: WorldState,
        grid: OccupancyGrid | None,
        command: Command,
        filtered: Command | None,
        applied: Command | None,
        reacted_to: tuple[int, ...],
    ) -> None:
        """A decision point in `world`: the agent's `command`, the safety layer's verdict (`filtered`,
        None when not asked), what the maneuver got (`applied`) and the vehicles the layer reacted to."""
        scores, name = self.pending_scores or (None, "")
        self.pending_scores = None
        decision = Decision(world.time, command, filtered, applied, scores, name, world, grid)
        self.buffers.decisions.append(decision)
        masked = filtered is not None and filtered is not command
        self.safety_reacted = reacted_to if masked else ()
        if masked:
            self._event(world.time, f"masked {command.name}: the gap in the target lane is unsafe", "WARN")
        self.draw_path = True

    def handed_over(
        self, time: float, spread: float, threshold: float, fallback: str, command: Command
    ) -> None:
        """The decision at `time` [s] went to the `fallback` agent, which chose `command`: the
        ensemble's members disagreed by `spread` [Q-value], above the gate's `threshold`."""
        self._event(
            time,
            f"uncertain: the members disagree by {spread:.2f} > {threshold:.2f}; "
            f"{fallback} decides {command.name}",
            "WARN",
        )

    def tick(
        self,
        tick: Tick,
        aborted: int,
        reacted_to: tuple[int, ...],
        emergency: tuple[int | None, int, str],
        monitor: SafetyMonitor,
        solve_s: float | None,
    ) -> None:
        """One control tick: the `tick` record, the safety layer's abort count and the vehicles it
        last reacted to, emergency braking's (vehicle braked for, activations, the latest activation's
        cause), the safety monitor, and the
        controller's time for this tick [s] (None when it measured none)."""
        world, reference, actuation = tick.world, tick.reference, tick.actuation
        time = world.time
        self.ticks += 1
        if aborted > self.last_aborted:
            self.last_aborted = aborted
            self.safety_reacted = reacted_to
            self._event(time, "lane change aborted: its gap closed", "WARN")
        cause, activations, why = emergency
        if activations > self.last_activations:
            self.last_activations = activations
            self._event(time, f"emergency braking for vehicle {cause} ({why})", "ERROR")
        phase = (
            f"change lane {tick.lane} -> {tick.target}" if tick.changing_lane else f"keep lane {tick.lane}"
        )
        if phase != self.phase:
            self._phase(
                time, phase if tick.changing_lane or "change" not in self.phase else f"{phase} (done)"
            )
            self.draw_path = True
        if self.draw_path:
            self._reference_path(tick)
        reacted = self.safety_reacted + ((cause,) if cause is not None else ())
        self._world(world, tuple(leader.vehicle for leader in reference.leaders), reacted)
        ego = world.ego_state()
        add = self.buffers.add
        add("control/steering", actuation.steering)
        add("control/acceleration", actuation.acceleration)
        add("control/lateral_error", ego.d - reference.d)
        course = math.atan2(reference.d_dot, max(ego.speed, 0.1))
        add("control/heading_error", ego.heading - course)
        add("control/solve_time", math.nan if solve_s is None else 1e3 * solve_s)
        add("ego/d_reference", reference.d)
        add("maneuver/lane", tick.lane)
        add("maneuver/target_lane", tick.target)
        self._safety(time, world, monitor)

    def sensed(self, detected: WorldState, tracked: WorldState | None) -> None:
        """What the sensor detected this tick and, with the tracker on, its confirmed tracks."""
        lane = detected.lanes[0]
        tracks = np.zeros((0, 2)) if tracked is None else lane_points(lane, tracked.s[1:], tracked.d[1:])
        points = lane_points(lane, detected.s[1:], detected.d[1:])
        self.buffers.sensed.append((detected.time, points, tracks))

    def _world(self, world: WorldState, leaders: tuple[int, ...], reacted: tuple[int, ...] = ()) -> None:
        """A snapshot to draw at `close` (its vehicles' arrays, `Frame`), with the ids of the ego's
        leaders and of the vehicles the safety layer or emergency braking reacted to."""
        buffers = self.buffers
        buffers.frames.append(Frame.of(world))
        buffers.marked.append((leaders, reacted))
        buffers.add("ego/speed", float(world.speed[0]))
        buffers.add("ego/d", float(world.d[0]))

    def _safety(self, time: float, world: WorldState, monitor: SafetyMonitor) -> None:
        """The TTC to the leader in the ego's lane, R157's distance, and the monitor's events."""
        lane = world.ego_lane
        leader = neighbours(world, lane)[0] if 0 <= lane < world.lanes_count else None
        speed = float(world.speed[0])
        ttc = TTC_CAP_S
        if leader is not None and leader.gap > 0 and speed > leader.speed:
            ttc = min(TTC_CAP_S, leader.gap / (speed - leader.speed))
        self.buffers.add("safety/ttc", ttc)
        below = leader is not None and leader.gap < r157_min_following_distance(speed)
        self.buffers.add("safety/below_min_distance", float(below))
        if below != self.below:
            self.below = below
            text = (
                "below R157's minimum following distance" if below else "back above R157's minimum distance"
            )
            self._event(time, text, "WARN" if below else "INFO")
        if monitor.min_ttc_s < self.last_min_ttc:
            self.last_min_ttc, self.min_ttc_time = monitor.min_ttc_s, time
        if monitor.collision is not None and not self.collided:
            self.collided = True
            fault = "at fault" if monitor.collision.at_fault else "not at fault"
            self._event(time, f"collision: {monitor.collision.kind} ({fault})", "CRITICAL")
        if monitor.road_departure and not self.departed:
            self.departed = True
            self._event(time, "road departure", "CRITICAL")

    def _reference_path(self, tick: Tick) -> None:
        """The reference the maneuver follows, from now to `REFERENCE_HORIZON_S` ahead, in world
        coordinates [m] (the ego assumed to keep its speed along the road)."""
        self.draw_path = False
        reference, world = tick.reference, tick.world
        if reference.lateral is None:
            return
        times = reference.time + np.arange(0.0, REFERENCE_HORIZON_S + 1e-9, REFERENCE_STEP_S)
        d, _ = reference.lateral.samples(times)
        s = float(world.s[0]) + float(world.speed[0]) * (times - reference.time)
        self.buffers.paths.append((reference.time, lane_points(world.lanes[0], s, d).astype(np.float32)))

    def _event(self, time: float, text: str, level: str) -> None:
        self.buffers.events.append((time, text, level))

    def _phase(self, time: float, phase: str) -> None:
        self.phase = phase.removesuffix(" (done)")
        self.buffers.phases.append((time, phase))

    def close(self) -> Path:
        """Write the recording to `path` (whole, via a temporary name beside it): its path."""
        if self.first is None:
            raise RuntimeError("an episode recording is written after its episode started")
        if self.min_ttc_time is not None:
            self._event(self.min_ttc_time, f"minimum TTC of the episode: {self.last_min_ttc:.2f} s", "INFO")
        write_recording(self.path, self.title, self.buffers)
        return self.path


def episode_recording(
    config: RunConfig, folder: Path | None, name: str, seed: int
) -> EpisodeRecording | None:
    """The recording of one episode of `config` as `folder/name.rrd`, or None without a folder."""
    if folder is None:
        return None
    title = (
        f"{config.planner.agent} + {config.controller.type}, {config.scenario or 'configured world'}, "
        f"{config.sim.plant} plant, seed {seed}"
    )
    return EpisodeRecording(folder / f"{name}.rrd", title)
