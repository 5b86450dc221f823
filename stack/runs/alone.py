"""One seeded episode driven alone, on the per-world loop: `run_episode` and its parts. What a run
does episode by episode (`stack.runs.episodes`) and what a batch runs again alone to judge a
collision it has no history of (`stack.runs.batch_episodes`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from planner.agents import Agent, Gate, Scored, decide, sees_permitted
from records import Command, child_seed
from stack.agents.oracle import Oracle
from stack.loop.closed_loop import ClosedLoop
from stack.loop.recording import episode_recording
from stack.results.episode_result import EpisodeResult
from stack.runs.kept import kept_adapter, kept_agent
from stack.settings.run import RunConfig
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
