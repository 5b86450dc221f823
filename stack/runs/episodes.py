"""Running seeded episodes: one at a time or spread over processes, results in episode order."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import closing
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from tqdm import tqdm

from planner.agents import Agent, Gate, Scored, decide, sees_permitted
from planner.factory import model_label, model_path
from records import Command, child_seed
from stack.agents.oracle import Oracle
from stack.loop.closed_loop import ClosedLoop
from stack.loop.recording import episode_recording
from stack.results.episode_result import EpisodeResult, summarize
from stack.runs.batched_episodes import RAY_BATCH_WORLDS, batch_refusal, batches, run_batched
from stack.runs.kept import kept_adapter, kept_agent
from stack.runtime.executors import completed
from stack.settings.drivers import HIGHWAY_ENV
from stack.settings.run import RunConfig, drivers_of
from stack.sim.highway import HighwayAdapter


def agent_step(loop: ClosedLoop, agent: Agent) -> int:
    """Perceive, let `agent` decide on its own encoding, act until the next decision; ticks run.
    A recorded loop also gets the agent's scores of the decision, when it has them (`Scored`)."""
    grid = loop.perceive()
    observation = None
    if isinstance(agent, Oracle):
        command = agent.plan(loop)
    else:
        observation = loop.observation(grid, agent.encoding, sees_permitted(agent))
        command = (
            gated_decision(loop, agent, observation)
            if isinstance(agent, Gate)
            else decide(agent, observation)
        )
    if loop.recording is not None and isinstance(agent, Scored):
        seen = observation if observation is not None else np.empty(0)
        loop.recording.scores(agent.scores(seen), agent.score_name)
    return loop.act(command).ticks


def gated_decision(loop: ClosedLoop, agent: Gate, observation: np.ndarray) -> Command:
    """The gated ensemble's command on `observation`, or, where its members disagree above the
    threshold, its fallback's on the fallback's own view of the same reading (counted by the loop)."""
    gated = agent.gate(observation)
    if not gated.handed[0]:
        return Command(int(gated.actions[0]))
    fallback = agent.fallback
    seen = loop.observation(
        loop.perceive_as(fallback.grid_config), fallback.encoding, sees_permitted(fallback)
    )
    command = decide(fallback, seen)
    loop.hand_over(float(gated.disagreement[0]), agent.threshold, agent.fallback_name, command)
    return command


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


def run(
    config: RunConfig,
    video: bool = False,
    progress: bool = True,
    jobs: int = 1,
    ray: str | None = None,
    on_finished: Callable[[EpisodeResult], None] | None = None,
    done: Sequence[EpisodeResult] = (),
    record: Path | None = None,
    snapshot: bool = True,
) -> RunResults:
    """Run `config.episodes` seeded episodes over `jobs` processes, or as Ray tasks with `ray` (an
    address, see `stack.runtime.executors`), as batches of worlds where the config allows
    (`stack.runs.batched_episodes`); results are ordered by episode, identical for any `jobs`, `ray`
    or batching. Here a batch hands on each episode as it ends; over processes or Ray a batch comes
    whole, and a stop loses the batches under way. With `video`, episode 0 (unless done) runs here
    and keeps its frames; with `snapshot` (the default), it runs alone and keeps its road's
    snapshot (a batch keeps none). `done` are episodes an earlier run of `config` finished: they
    count as they are and are not run again. Ctrl-C keeps the finished episodes
    (`summary["interrupted"]`); `on_finished` sees each as it finishes (if it raises, the episodes
    still running are stopped before the error goes on).
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

    stepped_alone = stepping_reason(config, record)
    try:
        if (video or snapshot) and pending and pending[0] == 0:
            finished(run_episode(config, pending.pop(0), frames if video else None, record))
        if stepped_alone is None:
            split = batches(pending, jobs) if ray is None else batches(pending, 1, RAY_BATCH_WORLDS)
            if ray is None and (jobs <= 1 or len(split) <= 1):
                for batch in split:
                    run_batched(config, batch, on_finished=finished)
            else:
                batched = partial(run_batched, config)
                with closing(completed(batched, split, jobs, ray)) as batches_coming:
                    for _, results_of_batch in batches_coming:
                        for result in results_of_batch:
                            finished(result)
        else:
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
        **drivers_entry(config),
        agent=config.planner.agent,
        model=model_label(model_path(config.planner.agent, config.planner.model)),
        controller=config.controller.type,
        backend=config.sim.backend,
        plant=config.sim.plant,
        seed=config.seed,
        stepping="per-world" if stepped_alone else "batched",
        **({"stepping_reason": stepped_alone} if stepped_alone else {}),
        interrupted=interrupted,
    )
    return RunResults(summary=summary, episodes=ordered, frames=frames)


def drivers_entry(config: RunConfig) -> dict[str, object]:
    """The summary's `drivers` (the traffic's driver population, `stack.sim.drivers`), left out for
    highway-env's own drivers (summaries of runs before populations stay as they were)."""
    drivers = drivers_of(config.highway)
    return {} if drivers == HIGHWAY_ENV else {"drivers": drivers}


def stepping_reason(config: RunConfig, record: Path | None) -> str | None:
    """Why `config`'s episodes run one world at a time (one line), or None: they run as batches of
    worlds (`batch_refusal`; a recorded run steps each world alone to record it). A batched run
    still runs its episode 0 alone when it keeps that episode's video or road snapshot."""
    if record is not None:
        return "recorded episodes (--record) run one world at a time"
    return batch_refusal(config)
