"""The closed loop: perceive, decide (every decision period or when a maneuver ends), track.

Each control tick reads like do-mpc's loop: `grid = perception.build(world)`,
`command = decide(agent, observation)`, `actuation = controller.step(state, reference, dt)`,
`world = plant.step(actuation)`.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from multiprocessing import get_context

import numpy as np
from tqdm import tqdm

from controllers.pid import AdaptiveCruise, PIDTracker
from controllers.types import EgoState, Leader, Reference
from perception.grid import GridConfig, OccupancyGridBuilder
from perception.neighbours import leaders
from perception.plot import grid_panel
from perception.sensor import SensorModel
from perception.types import WorldState
from planner.agents import Agent, decide
from planner.factory import make_agent
from stack.config import ControllerConfig, RunConfig
from stack.highway import HighwayAdapter
from stack.maneuver import Maneuver
from stack.metrics import EpisodeRecorder, EpisodeResult, summarize

SNAPSHOT_TIME_S = 10.0
"""Each episode keeps the (world, grid) of its first decision at or after this time [s]."""


def grid_config(config: RunConfig) -> GridConfig:
    return GridConfig(**config.perception.model_dump(exclude={"sensor"}))


def make_controller(config: ControllerConfig) -> PIDTracker:
    cruise = AdaptiveCruise(config.time_gap_s, config.standstill_gap_m, config.comfort_decel_mps2)
    return PIDTracker(cruise)


def ego_state(world: WorldState, lane: int) -> EgoState:
    """The ego in the frame of `lane`: lateral offset, heading relative to the lane, speed."""
    ego = world.ego
    return EgoState(d=ego.d, heading=ego.heading - world.lanes[lane].heading_at(ego.s), speed=ego.speed)


@dataclass
class Episode:
    """Everything one closed-loop episode needs; `frames` collects RGB frames when rendering."""

    config: RunConfig
    adapter: HighwayAdapter
    agent: Agent
    frames: list[np.ndarray] = field(default_factory=list)

    def run(self, episode: int, seed: int) -> EpisodeResult:
        config, adapter = self.config, self.adapter
        builder = OccupancyGridBuilder(grid_config(config))
        sensor = SensorModel(config.perception.sensor, seed)
        controller = make_controller(config.controller)
        world = adapter.reset(seed)
        maneuver = Maneuver(world, config.controller.lane_change_duration_s)
        recorder = EpisodeRecorder(world)
        ticks_to_decision = 0
        snapshot = None
        while not adapter.done:
            if maneuver.update(world):
                ticks_to_decision = 0
            if not maneuver.changing_lane and ticks_to_decision <= 0:
                self.last_grid = builder.build(sensor.observe(world))
                if snapshot is None or snapshot[0].time < SNAPSHOT_TIME_S:
                    snapshot = (world, self.last_grid)
                command = decide(self.agent, self.last_grid.to_paper_state())
                maneuver.command(command, world)
                ticks_to_decision = config.decision_ticks
            d, d_dot, d_ddot = maneuver.reference(world.time)
            reference = Reference(
                d,
                d_dot,
                d_ddot,
                set_speed=config.controller.set_speed_mps,
                leaders=tuple(Leader(*lead) for lead in leaders(world, maneuver.occupied_lanes)),
            )
            actuation = controller.step(ego_state(world, maneuver.lane), reference, adapter.dt)
            world = adapter.step(actuation)
            recorder.record(world)
            if adapter.rendering:
                frame = adapter.render()
                self.frames.append(np.vstack([frame, grid_panel(self.last_grid, frame.shape[1])]))
            ticks_to_decision -= 1
        result = recorder.result(episode, seed, adapter.terminated, maneuver.lane_changes, adapter.dt)
        result.snapshot = snapshot
        return result


@dataclass
class RunResults:
    summary: dict
    episodes: list[EpisodeResult]
    frames: list[np.ndarray]


def run_episode(config: RunConfig, episode: int, frames: list[np.ndarray] | None = None) -> EpisodeResult:
    """Episode `episode` of `config` (seed = config.seed + episode), with a fresh env and agent so
    its result does not depend on which process runs it or what ran before; `frames`, when
    given, collects the rendered frames."""
    seed = config.seed + episode
    agent = make_agent(config.planner.agent, config.highway.lanes_count, grid_config(config), seed)
    with HighwayAdapter(config.highway, config.sim.backend, render=frames is not None) as adapter:
        return Episode(config, adapter, agent, frames if frames is not None else []).run(episode, seed)


def run(config: RunConfig, video: bool = False, progress: bool = True, jobs: int = 1) -> RunResults:
    """Run `config.episodes` seeded episodes over `jobs` processes; results are ordered by episode,
    identical for any `jobs`. With `video`, episode 0 runs here and keeps its frames. Ctrl-C keeps
    the finished episodes (`summary["interrupted"]`)."""
    frames: list[np.ndarray] = []
    results: dict[int, EpisodeResult] = {}
    pending = list(range(config.episodes))
    interrupted = False
    bar = tqdm(total=config.episodes, unit="episode", disable=not progress)

    def finished(result: EpisodeResult) -> None:
        results[result.episode] = result
        bar.update(1)
        bar.set_postfix(crashes=sum(r.crashed for r in results.values()))

    try:
        if video:
            finished(run_episode(config, pending.pop(0), frames))
        if jobs <= 1:
            for episode in pending:
                finished(run_episode(config, episode))
        else:
            with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
                futures = [pool.submit(run_episode, config, episode) for episode in pending]
                try:
                    for future in as_completed(futures):
                        finished(future.result())
                except KeyboardInterrupt:
                    for future in futures:
                        future.cancel()
                    raise
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
    if not results:
        raise KeyboardInterrupt
    ordered = [results[episode] for episode in sorted(results)]
    summary = summarize(
        ordered,
        agent=config.planner.agent,
        controller=config.controller.type,
        backend=config.sim.backend,
        seed=config.seed,
        interrupted=interrupted,
    )
    return RunResults(summary=summary, episodes=ordered, frames=frames)
