"""The closed loop: perceive, decide (every decision period or when a maneuver ends), track.

Each control tick reads like do-mpc's loop: `grid = perception.build(world)`,
`command = decide(agent, observation)`, `actuation = controller.step(state, reference, dt)`,
`world = plant.step(actuation)`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from controllers.pid import AdaptiveCruise, PIDTracker
from controllers.types import EgoState, Leader, Reference
from perception.grid import GridConfig, OccupancyGridBuilder
from perception.neighbours import leaders
from perception.types import WorldState
from planner.agents import Agent, decide
from planner.factory import make_agent
from stack.config import ControllerConfig, RunConfig
from stack.highway import HighwayAdapter
from stack.maneuver import Maneuver
from stack.metrics import EpisodeRecorder, EpisodeResult, summarize


def grid_config(config: RunConfig) -> GridConfig:
    p = config.perception
    return GridConfig(p.cell_length_m, p.cells_ahead, p.cells_behind)


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

    def run(self, episode: int, seed: int, on_tick: Callable[[], None] | None = None) -> EpisodeResult:
        config, adapter = self.config, self.adapter
        builder = OccupancyGridBuilder(grid_config(config))
        controller = make_controller(config.controller)
        world = adapter.reset(seed)
        maneuver = Maneuver(world, config.controller.lane_change_duration_s)
        recorder = EpisodeRecorder(world)
        ticks_to_decision = 0
        while not adapter.done:
            if maneuver.update(world):
                ticks_to_decision = 0
            if not maneuver.changing_lane and ticks_to_decision <= 0:
                command = decide(self.agent, builder.build(world).to_paper_state())
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
                self.frames.append(adapter.render())
            ticks_to_decision -= 1
            if on_tick:
                on_tick()
        return recorder.result(episode, seed, adapter.terminated, maneuver.lane_changes, adapter.dt)


@dataclass
class RunResults:
    summary: dict
    episodes: list[EpisodeResult]
    frames: list[np.ndarray]


def run(config: RunConfig, video: bool = False, progress: bool = True) -> RunResults:
    """Run `config.episodes` seeded episodes (seed, seed + 1, ...); with `video`, keep the frames
    of the first episode."""
    adapter = HighwayAdapter(config.highway)
    agent = make_agent(config.planner.agent, config.highway.lanes_count, grid_config(config), config.seed)
    results: list[EpisodeResult] = []
    frames: list[np.ndarray] = []
    interrupted = False
    ticks_per_episode = round(config.highway.duration * config.highway.simulation_frequency)
    bar = tqdm(total=config.episodes * ticks_per_episode, unit="tick", disable=not progress)
    try:
        for episode in range(config.episodes):
            seed = config.seed + episode
            if video and episode == 0:
                with HighwayAdapter(config.highway, render=True) as render_adapter:
                    runner = Episode(config, render_adapter, agent, frames)
                    results.append(runner.run(episode, seed, on_tick=lambda: bar.update(1)))
            else:
                runner = Episode(config, adapter, agent)
                results.append(runner.run(episode, seed, on_tick=lambda: bar.update(1)))
            bar.set_postfix(crashes=sum(r.crashed for r in results))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
        adapter.close()
    if not results:
        raise KeyboardInterrupt
    summary = summarize(
        results,
        agent=config.planner.agent,
        controller=config.controller.type,
        seed=config.seed,
        interrupted=interrupted,
    )
    return RunResults(summary=summary, episodes=results, frames=frames)
