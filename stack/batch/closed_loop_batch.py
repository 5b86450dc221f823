"""N closed loops stepped together: `ClosedLoopBatch`, the batched `ClosedLoop.act` of a run config
on the PID tracker and the kinematic plant, each world the loop the `vector` backend drives alone,
bit for bit, through its sensor model when it has one (`perception.sensor.SensorBatch`).

The traffic is a `TrafficBatch`; the ego's side of every tick (reference, leaders, PID, cruise,
emergency braking, the safety layer's abort, road departure) is three compiled calls over all the
worlds (`stack.batch.loop_kernels`); between them numpy computes what it computes for one
world (the snapshot's lane frame, each footprint's sine and cosine) over the whole batch. No
Python runs per world per tick: only a world's reset (highway-env spawns its road) is per world."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from common.neighbours import lateral_drifts, lateral_extents
from controllers.emergency import EmergencyBraking
from controllers.lateral import LateralPID
from controllers.reference import lane_keeping
from controllers.tracker import PIDTracker, make_controller
from perception.sensor import SensorBatch, SensorModel
from perception.tracking import TrackerBatch
from planner.safety import permitted_batch, safety_settings
from records import WorldState
from records.batch import WorldBatch
from stack.batch.ego_records import MEMORY_COLUMNS, ActedBatch
from stack.batch.loop_kernels import (
    ControllerArrays,
    EgoLaws,
    ManeuverArrays,
    ManeuverSettings,
    control,
    decide,
    settle,
)
from stack.fault.emergency_causes import BrakingsByCause, CausesBatch, tracked_true_rows
from stack.loop.metrics import EpisodeMetricsBatch
from stack.loop.safety_metrics import classify_collision, monitored
from stack.results.episode_fields import record_fields
from stack.results.episode_measures import measured
from stack.results.episode_result import EpisodeResult
from stack.settings.run import RunConfig, episode_sensor, training_worlds
from stack.sim.batch.traffic import TrafficBatch
from stack.sim.highway import snapshot


def refusal(config: RunConfig) -> str | None:
    """Why a batch cannot run `config` (one line), or None: the batch drives the PID tracker on
    the kinematic plant, its layers acting on what the sensor reports; MPC and plug-in
    controllers, the dynamic plant and the ground-truth ablation run one world at a time
    (`HierarchicalHighwayEnv`)."""
    control_config, pid = config.controller, config.controller.pid
    if control_config.type != "pid":
        return f"batched worlds run the PID tracker, not controller.type {control_config.type!r}"
    if config.sim.plant != "kinematic" or pid.model not in ("plant", "kinematic"):
        return "batched worlds run the kinematic plant and a PID inverting it (sim.plant: kinematic)"
    if config.perception.control_on_ground_truth and any(map(_sensed, training_worlds(config).values())):
        return "batched worlds act on what the sensor reports: perception.control_on_ground_truth must be off"
    return None


def _sensed(config: RunConfig) -> bool:
    """Whether some episode of `config` may be seen through a sensor model (`episode_sensor`)."""
    return config.perception.sensor.enabled or config.highway.random_traffic is not None


class ClosedLoopBatch:
    """`worlds` closed loops of one run config: `reset_world`, `act(commands, ticks)`, the worlds as
    the layers see them (`batch`, the truth, and `perceived`, what the sensor reports: both
    `WorldBatch`), and per world `crashed` / `done`."""

    def __init__(self, config: RunConfig, worlds: int, metrics: bool = False) -> None:
        """With `metrics`, each world's episode is measured as the per-world loop measures it
        (`result`); training needs none of it."""
        refused = refusal(config)
        if refused is not None:
            raise ValueError(refused)
        self.config = config
        self.members = list(training_worlds(config).values())
        """The worlds an episode is one of: `config` alone, or the members of its `train.scenarios`."""
        self.traffic = TrafficBatch([member.highway for member in self.members], worlds)
        self.worlds, self.dt = worlds, self.traffic.dt
        control_config, safety = config.controller, config.planner.safety
        self.min_speed = control_config.min_lane_change_speed_mps
        max_course = math.radians(control_config.lane_change_max_course_deg)
        self.settings = ManeuverSettings(
            control_config.lane_change_duration_s,
            self.min_speed,
            math.tan(max_course),
            control_config.set_speed_mps,
            control_config.cut_in_lookahead_s,
            control_config.weaver_wary_s,
        )
        self.safety = safety_settings(safety)
        self.abort_lookahead_s = safety.abort_lookahead_s
        tracker = make_controller(control_config, self.dt)
        assert isinstance(tracker, PIDTracker) and isinstance(tracker.lateral, LateralPID)
        lateral, cruise, c = tracker.lateral, tracker.cruise, control_config
        braking = EmergencyBraking(c.emergency_decel_mps2, c.comfort_decel_mps2, c.emergency_ttc_s)
        self.laws = EgoLaws(lateral.limits, cruise.speed_pid.terms, cruise.law, braking.limits)
        self.lane = np.zeros(worlds, dtype=np.int64)
        self.target = np.zeros(worlds, dtype=np.int64)
        self.coef, self.profile = np.zeros((worlds, 6)), np.zeros((worlds, 4))
        self.clock = np.zeros((worlds, 3))
        self.counts = np.zeros((worlds, 3), dtype=np.int64)
        self.lateral, self.speed_pi = np.zeros((worlds, 4)), np.zeros((worlds, 3))
        self.flags = np.zeros((worlds, 3), dtype=np.int64)
        self.seen = np.zeros((worlds, 0), dtype=np.int64)
        self.seen_speed, self.seen_slowing = np.zeros((worlds, 0)), np.zeros((worlds, 0))
        self.moving, self.weaved_at = np.zeros((worlds, 0)), np.zeros((worlds, 0))
        self.departed, self.crashed = np.zeros(worlds, dtype=bool), np.zeros(worlds, dtype=bool)
        self.truncated = np.zeros(worlds, dtype=bool)
        self.batch: WorldBatch | None = None
        self.perceived: WorldBatch | None = None
        self.sensor = SensorBatch(worlds) if any(map(_sensed, self.members)) else None
        tracking = config.perception.tracker
        self.tracker = None
        if self.sensor is not None and tracking.mode != "off":
            self.tracker = TrackerBatch(tracking, worlds)
        self.detected: WorldBatch | None = None
        self.slots = np.zeros((worlds, 0), dtype=np.int64)
        self.vehicle_room = 0
        self.metrics = EpisodeMetricsBatch(worlds, self.dt) if metrics else None
        self.causes = CausesBatch(worlds) if metrics else None
        """Emergency braking's causes, counted with the metrics (training needs none)."""

    def _memory(self, vehicles: int, phantoms: int = 0) -> None:
        """Emergency braking's per-vehicle memory (`seen`, `seen_speed`, `seen_slowing`: what it
        kept of each vehicle, `stack.batch.loop_kernels.emergency_acceleration`) and the weave
        memory (`moving`, `weaved_at`: `controllers.weaving`), grown to room for `vehicles` a world
        (a column per snapshot row), then `phantoms` (a column per false positive's id)."""
        more = vehicles - self.vehicle_room
        if more > 0:
            at = [self.vehicle_room] * more
            for name, empty in MEMORY_COLUMNS:
                setattr(self, name, np.insert(getattr(self, name), at, empty, axis=1))
            self.vehicle_room = vehicles
        more = self.vehicle_room + phantoms - self.seen.shape[1]
        if more > 0:
            for name, empty in MEMORY_COLUMNS:
                setattr(self, name, np.pad(getattr(self, name), ((0, 0), (0, more)), constant_values=empty))

    def _sense(self, worlds: np.ndarray, warm_up: bool = False) -> None:
        """`perceived` and the memory `slots` of its rows after a frame: the worlds flagged observed
        anew through their sensors (the truth itself without a sensor model), tracked in the worlds
        that track (`perception.tracking.TrackerBatch`; memory column `vehicle_room` + 1 + the track's
        slot, past the truth's columns, so another world's growth moves it with them; its weave memory
        emptied for a track born there, as one world's keys it by the new track's id), with no
        time passed since the last frame when `warm_up` (the tracker's start, as `Tracker.warm_up`)."""
        batch = self.batch
        assert batch is not None
        if self.sensor is None:
            self.perceived = batch
            if self.slots.shape[1] != batch.s.shape[1]:
                self.slots = np.tile(np.arange(batch.s.shape[1]), (self.worlds, 1))
            return
        sensed = self.sensor.sense(batch, worlds)
        phantoms = int(sensed.phantom.max(initial=-1)) + 1
        tracks = 0 if self.tracker is None else 1 + self.tracker.config.max_tracks
        self._memory(self.traffic.arrays.vehicles, max(phantoms, tracks))
        source = np.where(sensed.phantom >= 0, self.vehicle_room + sensed.phantom, sensed.source)
        self.detected = sensed.batch
        if self.tracker is None:
            self.perceived, self.slots = sensed.batch, source
            return
        idents = self.tracker.tracks.ident.copy()
        tracked = self.tracker.update(sensed.batch, worlds, 0.0 if warm_up else self.dt)
        tracks_from = self.vehicle_room + 1
        born_world, born_slot = np.nonzero(self.tracker.tracks.ident != idents)
        born = tracks_from + born_slot
        self.moving[born_world, born], self.weaved_at[born_world, born] = 0.0, -np.inf
        self.perceived = tracked.batch
        detected_slots = np.zeros((self.worlds, tracked.slot.shape[1]), dtype=np.int64)
        detected_slots[:, : source.shape[1]] = source
        track_slots = tracks_from + np.maximum(tracked.slot, -1)
        self.slots = np.where(self.tracker.tracked[:, None], track_slots, detected_slots)

    @property
    def done(self) -> np.ndarray:
        """Per world: its episode ended (crash, duration, road departure) and it awaits a reset."""
        return self.crashed | self.truncated | self.departed

    @property
    def changing(self) -> np.ndarray:
        """Per world: a lane change runs (a command given now is ignored)."""
        return self.lane != self.target

    def close(self) -> None:
        self.traffic.close()

    def permitted(self) -> np.ndarray:
        """(worlds, 3) float32: `ClosedLoop.permitted()` of every world."""
        batch, perceived = self.batch, self.perceived
        if batch is None or perceived is None:
            raise ValueError("reset the worlds before asking what they permit")
        safety = self.config.planner.safety
        return permitted_batch(safety, perceived, self.lane, self.changing, batch.speed[:, 0], self.min_speed)

    def reset(self, seeds: Sequence[int], members: Sequence[int] | None = None) -> None:
        """Reset every world, world k with traffic seed `seeds[k]` (as mix member `members[k]`)."""
        if len(seeds) != self.worlds:
            raise ValueError(f"one seed per world: {self.worlds} worlds, {len(seeds)} seeds")
        self.reset_worlds(range(self.worlds), seeds, members)

    def reset_worlds(
        self, worlds: Sequence[int], seeds: Sequence[int], members: Sequence[int] | None = None
    ) -> None:
        """Reset the worlds `worlds`, each with its traffic seed and, in a mix, its member (an index
        of `members`): its road spawned anew and its ego's maneuver, controllers, emergency braking
        and counts as `ClosedLoop.reset` leaves them."""
        if members is None:
            if len(self.members) > 1:
                raise ValueError("a train.scenarios mix: name each world's member (members=)")
            members = [0] * len(seeds)
        for world, seed, member in zip(worlds, seeds, members, strict=True):
            self.traffic.reset_world(world, int(seed), int(member))
            if self.sensor is not None:
                sensor = episode_sensor(self.members[member], int(seed))
                self.sensor.reset_world(world, SensorModel(sensor, int(seed)))
                if self.tracker is not None:
                    self.tracker.reset_world(world, sensor)
        self._memory(self.traffic.arrays.vehicles)
        self.batch = self.traffic.arrays.world_batch()
        reset = np.zeros(self.worlds, dtype=bool)
        reset[list(worlds)] = True
        self._sense(reset, warm_up=True)
        if self.tracker is not None:
            warming = reset & self.tracker.tracked
            for _ in range(self.config.perception.tracker.confirm_frames - 1):
                self._sense(warming, warm_up=True)
        arrays = self.traffic.arrays
        for world in worlds:
            lane = int(arrays.lane[world, arrays.ego[world]])
            self.lane[world] = self.target[world] = lane
            keeping = lane_keeping(
                float(self.batch.lane_offsets[world, lane]), float(self.traffic.time[world])
            )
            self.coef[world] = keeping.coefficients
            self.profile[world] = (keeping.t0, keeping.duration, keeping.d1, keeping.peak_lateral_speed)
            self.clock[world] = (0.0, 0.0, 1.0)
            self.counts[world] = self.flags[world] = 0
            self.lateral[world] = self.speed_pi[world] = 0.0
            for name, empty in MEMORY_COLUMNS:
                getattr(self, name)[world] = empty
            self.departed[world] = self.crashed[world] = self.truncated[world] = False
        if self.causes is not None:
            self.causes.reset(reset, self.batch, self.traffic.time, self.dt)
        if self.metrics is not None:
            self.metrics.reset(worlds, self.batch, self.traffic.arrays, self.traffic.time)

    def loaded(self) -> None:
        """What the layers read, anew after worlds were written in place (`stack.batch.loop_copies`)."""
        self._memory(self.traffic.arrays.vehicles)
        self.batch = self.traffic.arrays.world_batch()
        self._sense(np.ones(self.worlds, dtype=bool), warm_up=True)

    def _maneuver(self) -> ManeuverArrays:
        return ManeuverArrays(self.lane, self.target, self.coef, self.profile, self.clock, self.counts)

    def act(self, commands: np.ndarray, ticks: int, only: np.ndarray | None = None) -> ActedBatch:
        """`ClosedLoop.act(command, ticks)` in every world at once (or in the worlds flagged in
        `only`, the others left as they are): world k's command `commands[k]` (`Command` values)
        through the safety layer to the maneuver, then `ticks` control ticks, or fewer in a world
        whose episode ends first. Every world acting must be live (reset once done)."""
        live = np.ones(self.worlds, dtype=bool) if only is None else np.array(only, dtype=bool)
        outcome = self.command(commands, live)
        speeds = np.zeros((self.worlds, ticks))
        ran = np.zeros(self.worlds, dtype=np.int64)
        for tick in range(ticks):
            if not live.any():
                break
            self.tick(live)
            batch = self.batch
            assert batch is not None
            speeds[live, tick] = batch.speed[live, 0]
            ran[live] += 1
            live &= ~self.done
        assert self.batch is not None
        return ActedBatch(
            ran,
            outcome[:, 0] == 1,
            outcome[:, 1] == 1,
            outcome[:, 2] == 1,
            _mean_speeds(speeds, ran, self.batch),
        )

    def command(self, commands: np.ndarray, live: np.ndarray) -> np.ndarray:
        """A decision point in each world flagged `live` (`ClosedLoop.act`'s first part): world k's
        command `commands[k]` (`Command` values) through the safety layer to the maneuver, unless
        a lane change runs there. Per world (worlds, 3) 0/1: the command was considered, masked
        by the safety layer, refused by the maneuver."""
        perceived = self.perceived
        if perceived is None:
            raise ValueError("reset the worlds before acting")
        if (self.done & live).any():
            gone = np.flatnonzero(self.done & live).tolist()
            raise ValueError(f"worlds {gone} ended their episode: reset them before acting")
        commands = np.asarray(commands, dtype=np.int64)
        if commands.shape != (self.worlds,) or ((commands < 0) | (commands > 2)).any():
            raise ValueError(f"one command (0, 1, 2) per world: {self.worlds} worlds, got {commands!r}")
        outcome = np.zeros((self.worlds, 3), dtype=np.int64)
        reach = (perceived.lane_width + lateral_extents(perceived)) / 2
        decide(
            live, commands, self.traffic.time, perceived.columns(), reach, perceived.lane_width,
            self._maneuver(), self.safety, self.settings, outcome,
        )  # fmt: skip
        return outcome

    def tick(self, live: np.ndarray) -> np.ndarray:
        """One control tick in each world flagged `live` (`ClosedLoop.tick` and what `act` does
        after it): reference, actuation, the plant's frame, the sensor, the road departure and the
        maneuver's update, and the episode metrics when kept (`metrics`). Per world: a lane change
        completed on this tick (`Maneuver.update`)."""
        perceived, traffic, truth = self.perceived, self.traffic, self.batch
        assert perceived is not None and truth is not None
        actuation = np.zeros((self.worlds, 2))
        controller = ControllerArrays(
            self.lateral, self.speed_pi, self.seen, self.seen_speed, self.seen_slowing, self.flags,
            self.moving, self.weaved_at,
        )  # fmt: skip
        activations = self.flags[:, 1].copy()
        started = time.perf_counter()
        control(
            live, traffic.time, perceived.columns(), perceived.heading, perceived.lane_heading,
            lateral_extents(perceived), lateral_drifts(perceived, self.abort_lookahead_s),
            perceived.lane_width, self.slots, self._maneuver(), controller,
            self.safety, self.settings, self.laws, self.dt, actuation,
        )  # fmt: skip
        control_s = time.perf_counter() - started
        if self.causes is not None:
            self.causes.attribute(
                live, self.changing, traffic.time, self.flags, activations, self.vehicle_room,
                None if self.tracker is None else tracked_true_rows(
                    live & (self.flags[:, 1] > activations) & self.tracker.tracked, self.flags[:, 2],
                    self.slots, perceived, truth,
                ),
            )  # fmt: skip
        traffic.arrays.intent[:] = np.where(self.changing, self.target, -1)
        ended = traffic.step(actuation[:, 0], actuation[:, 1], live)
        batch = self.batch = traffic.arrays.world_batch()
        if self.causes is not None:
            self.causes.observe(live, batch, traffic.time, self.dt)
        self._sense(live)
        changing = self.changing
        settle(
            live, traffic.time, batch.columns(), batch.heading, batch.lane_heading,
            batch.lane_width, self._maneuver(), self.departed,
        )  # fmt: skip
        self.crashed |= ended.terminated
        self.truncated |= ended.truncated
        if self.metrics is not None:
            for world in self.metrics.record(
                live, batch, traffic.arrays, traffic.time, self.crashed, control_s
            ):
                crash = self.world_state(world)
                self.metrics.collided(world, classify_collision(crash, bool(changing[world])), crash.lanes)
        return changing & ~self.changing

    def result(self, world: int, episode: int, seed: int) -> EpisodeResult:
        """World `world`'s episode as `ClosedLoop.result` reports it (kept with `metrics`), run as
        episode `episode` with traffic seed `seed`; no grid snapshot; the controller's time per tick
        is the world's share of the batch's control step (reference, PID, cruise and braking)."""
        if self.metrics is None or self.causes is None:
            raise ValueError("a batch measures its episodes when made with metrics=True")
        counts, departed = self.counts[world], bool(self.departed[world])
        p50_ms, p95_ms = self.metrics.control_ms(world)
        return EpisodeResult(
            episode=episode,
            seed=seed,
            crashed=bool(self.crashed[world]),
            lane_changes=int(counts[0]),
            masked_commands=int(counts[1]),
            aborted_changes=int(counts[2]),
            emergency_brakings=int(self.flags[world, 1]),
            **record_fields(BrakingsByCause.of(self.causes.counts[world])),
            solve_ms_p50=p50_ms,
            solve_ms_p95=p95_ms,
            **measured(EpisodeResult, self.metrics.samples(world)),
            **record_fields(self.metrics.measured(world, departed)),
            **monitored(self.metrics.kept, world),
        )

    def world_state(self, world: int) -> WorldState:
        """World `world` as it stands, as the per-world loop's snapshot (`stack.sim.highway.snapshot`)."""
        _, ego = self.traffic.road(world)
        lanes = int(self.traffic.arrays.lane_count[world])
        return snapshot(ego.road, ego, float(self.traffic.time[world]), lanes)


def _mean_speeds(speeds: np.ndarray, ran: np.ndarray, batch: WorldBatch) -> np.ndarray:
    """Each world's mean of its first `ran` speeds, as `np.mean` of that world's list (the same
    pairwise sum per row); its ego's speed now where no tick ran."""
    means = batch.speed[:, 0].copy()
    for count in set(ran.tolist()) - {0}:
        rows = np.flatnonzero(ran == count)
        means[rows] = np.mean(speeds[rows, :count], axis=1)
    return means
