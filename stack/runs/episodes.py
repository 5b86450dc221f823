"""Running seeded episodes: one at a time or spread over processes, results in episode order."""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Sequence
from contextlib import closing
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from planner.agents import Agent, Scored, decide, sees_permitted
from planner.factory import make_agent, model_label, model_path
from records import LEARNED_AGENTS, child_seed
from stack.agents.oracle import Oracle
from stack.loop.closed_loop import ClosedLoop, grid_config
from stack.loop.recording import episode_recording
from stack.results.episode_result import EpisodeResult, summarize
from stack.runs.model_fit import check_road_fit
from stack.runtime.executors import completed
from stack.settings.run import RunConfig
from stack.sim.highway import HighwayAdapter

if TYPE_CHECKING:
    from planner.lookahead import LookaheadSetup


def build_agent(config: RunConfig, seed: int) -> Agent:
    """The agent `config.planner` names, for the run's road and grid; raises ValueError (one line)
    for a missing, unsafe or mismatched model file."""
    planner, lanes = config.planner, config.highway.lanes_count
    if planner.agent == "oracle":
        return Oracle.for_road(planner.oracle, lanes, grid_config(config))
    path = model_path(planner.agent, planner.model)
    setup = lookahead_setup(config) if planner.agent == "lookahead" else None
    agent = make_agent(planner.agent, lanes, grid_config(config), seed, path or planner.model, setup)
    expected = getattr(agent, "observation_size", None)
    grid = agent.grid_config or grid_config(config)
    if expected is not None:
        counts = config.highway.lane_counts
        check_road_fit(path or "", grid, agent.encoding, expected, counts, permitted=sees_permitted(agent))
    return agent


def lookahead_setup(config: RunConfig) -> LookaheadSetup:
    """What the lookahead agent takes from `config`: its settings, the maneuver's and the adaptive
    cruise's parameters, the safety layer's gaps."""
    from planner.lookahead import DrivingModel, LookaheadSetup

    control = config.controller
    driving = DrivingModel(
        set_speed=control.set_speed_mps,
        time_gap=control.time_gap_s,
        standstill_gap=control.standstill_gap_m,
        comfort_decel=control.comfort_decel_mps2,
        max_accel=control.pid.max_acceleration,
        kp_speed=control.pid.kp_speed,
        emergency_decel=control.emergency_decel_mps2,
        emergency_ttc=control.emergency_ttc_s,
        lane_change_s=control.lane_change_duration_s,
        max_course=math.radians(control.lane_change_max_course_deg),
        min_change_speed=control.min_lane_change_speed_mps,
    )
    return LookaheadSetup(config.planner.lookahead, driving, config.planner.safety)


def agent_step(loop: ClosedLoop, agent: Agent) -> int:
    """Perceive, let `agent` decide on its own encoding, act until the next decision; ticks run.
    A recorded loop also gets the agent's scores of the decision, when it has them (`Scored`)."""
    grid = loop.perceive()
    observation = None
    if isinstance(agent, Oracle):
        command = agent.plan(loop)
    else:
        observation = loop.observation(grid, agent.encoding, sees_permitted(agent))
        command = decide(agent, observation)
    if loop.recording is not None and isinstance(agent, Scored):
        seen = observation if observation is not None else np.empty(0)
        loop.recording.scores(agent.scores(seen), agent.score_name)
    return loop.act(command).ticks


def run_agent_episode(loop: ClosedLoop, agent: Agent, episode: int, seed: int) -> EpisodeResult:
    """Drive one episode: perceive, decide, act, until the episode ends."""
    loop.reset(seed)
    while not loop.done:
        agent_step(loop, agent)
    return loop.result(episode)


@dataclass
class RunResults:
    summary: dict
    episodes: list[EpisodeResult]
    frames: list[np.ndarray]


def run_episode(
    config: RunConfig, episode: int, frames: list[np.ndarray] | None = None, record: Path | None = None
) -> EpisodeResult:
    """Episode `episode` of `config` (seed = config.seed + episode); `frames`, when given, collects
    the rendered frames; with `record` (a folder), the episode is recorded there as
    `episode-NNNN.rrd` (`stack.loop.recording`; written by whichever process runs it). Its result
    does not depend on which process runs it, what ran before or whether it is recorded: the env a
    process keeps for a config is reset with the episode's seed (highway-env then rebuilds the road
    and reseeds every draw), and the learned agents it keeps are greedy, stateless policies over a
    model file that has not changed since it was checked."""
    seed = child_seed(config.seed, episode)
    agent = kept_agent(config, seed)
    recording = episode_recording(config, record, f"episode-{episode:04d}", seed)
    if frames is not None:
        with HighwayAdapter(
            config.highway, config.sim.backend, render=True, plant=config.sim.plant
        ) as adapter:
            loop = ClosedLoop(config, adapter, frames, grid=agent.grid_config, recording=recording)
            result = run_agent_episode(loop, agent, episode, seed)
    else:
        loop = ClosedLoop(config, kept_adapter(config), grid=agent.grid_config, recording=recording)
        result = run_agent_episode(loop, agent, episode, seed)
    if recording is not None:
        recording.close()
    return result


KEPT_PER_PROCESS = 4
"""Envs, and agents, a process keeps for the configs it ran last (a sweep's worker runs several)."""
_adapters: OrderedDict[tuple[str, ...], HighwayAdapter] = OrderedDict()
_agents: OrderedDict[tuple[object, ...], Agent] = OrderedDict()


def kept_adapter(config: RunConfig) -> HighwayAdapter:
    """This process's env for `config`'s road, backend and plant (made on first use)."""
    key = (config.highway.model_dump_json(), config.sim.backend, config.sim.plant)
    adapter = _adapters.get(key)
    if adapter is None:
        adapter = HighwayAdapter(config.highway, config.sim.backend, plant=config.sim.plant)
        _keep(_adapters, key, adapter).close()
    _adapters.move_to_end(key)
    return adapter


def kept_agent(config: RunConfig, seed: int) -> Agent:
    """`build_agent(config, seed)`; a learned agent (or an oracle over one) comes from this
    process's cache while its model file is unchanged: the seed does not reach it."""
    planner = config.planner
    learned = planner.agent if planner.agent != "oracle" else planner.oracle.base
    path = model_path(learned, planner.model if planner.agent != "oracle" else None)
    if learned not in LEARNED_AGENTS or path is None:
        return build_agent(config, seed)
    try:
        stat = Path(path).stat()
    except OSError:
        return build_agent(config, seed)
    road = config.model_dump_json(include={"planner", "perception", "highway", "scenario"})
    key = (road, str(path), stat.st_mtime_ns, stat.st_size, stat.st_ino)
    agent = _agents.get(key)
    if agent is None:
        agent = build_agent(config, seed)
        _keep(_agents, key, agent)
    _agents.move_to_end(key)
    return agent


def _keep(kept: OrderedDict, key: Any, value: Any) -> Any:
    """Keep `value` under `key`, at most `KEPT_PER_PROCESS` entries; the one dropped (or a dummy)."""
    kept[key] = value
    if len(kept) > KEPT_PER_PROCESS:
        return kept.popitem(last=False)[1]
    return _Nothing()


class _Nothing:
    def close(self) -> None:
        pass


def run(
    config: RunConfig,
    video: bool = False,
    progress: bool = True,
    jobs: int = 1,
    ray: str | None = None,
    on_finished: Callable[[EpisodeResult], None] | None = None,
    done: Sequence[EpisodeResult] = (),
    record: Path | None = None,
) -> RunResults:
    """Run `config.episodes` seeded episodes over `jobs` processes, or as Ray tasks with `ray` (an
    address, see `stack.runtime.executors`); results are ordered by episode, identical for any `jobs`
    or `ray`. With `video`, episode 0 (unless done) runs here and keeps its frames. `done` are
    episodes an earlier run of `config` finished: they count as they are and are not run again.
    Ctrl-C keeps the finished episodes (`summary["interrupted"]`); `on_finished` sees each as it
    finishes (if it raises, the episodes still running are stopped before the error goes on).
    `record`: a folder each episode run writes its recording into (`run_episode`)."""
    frames: list[np.ndarray] = []
    results: dict[int, EpisodeResult] = {episode.episode: episode for episode in done}
    pending = [episode for episode in range(config.episodes) if episode not in results]
    interrupted = False
    bar = tqdm(total=config.episodes, initial=len(results), unit="episode", disable=not progress)

    def finished(result: EpisodeResult) -> None:
        results[result.episode] = result
        bar.update(1)
        bar.set_postfix(crashes=sum(r.crashed for r in results.values()))
        if on_finished is not None:
            on_finished(result)

    try:
        if video and pending and pending[0] == 0:
            finished(run_episode(config, pending.pop(0), frames, record))
        task = partial(run_episode, config, record=record)
        with closing(completed(task, pending, jobs, ray)) as results_coming:
            for _, result in results_coming:
                finished(result)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
    if not results:
        raise KeyboardInterrupt
    ordered = [results[episode] for episode in sorted(results)]
    summary = summarize(
        ordered,
        scenario=config.scenario,
        agent=config.planner.agent,
        model=model_label(model_path(config.planner.agent, config.planner.model)),
        controller=config.controller.type,
        backend=config.sim.backend,
        plant=config.sim.plant,
        seed=config.seed,
        interrupted=interrupted,
    )
    return RunResults(summary=summary, episodes=ordered, frames=frames)
