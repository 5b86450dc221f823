"""Seeded episodes run as one batch of worlds (`ClosedLoopBatch`): what `drivestack run` and
`compare` use for every agent that decides on the grid alone, each episode's result the one the
per-world loop reports, outcome for outcome (`tests/test_batched_episodes.py`).

The worlds tick together; at a world's decision point (one decision period on, or the end of its
lane change, as `ClosedLoop.act` decides) its agent decides on the batched encoding of what its
sensor reports (`perception.grid.observe_batch`) and the command goes through the batched safety layer.
An agent that decides for many worlds at once (`planner.agents.BatchPolicy`: the lookahead) decides
for every world at a decision point in one call. The agent that plans on copies of the loop (the
oracle), the tabular encoding,
the grid's `traffic` feature, other controllers and plants, recordings and videos run one world
at a time (`batch_refusal` says why)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from perception.grid import BATCHED_FEATURES, observe_batch
from planner.agents import Agent, BatchPolicy, Gate, decide, sees_permitted
from records import Command, GridConfig, child_seed
from stack.batch.closed_loop_batch import ClosedLoopBatch, refusal
from stack.loop.closed_loop import grid_config
from stack.results.episode_result import EpisodeResult
from stack.runs.alone import run_episode
from stack.runs.kept import kept_agent
from stack.runtime.interrupts import raise_if_stopped
from stack.settings.run import RunConfig

BATCH_WORLDS = 64
"""The most episodes one batch runs at once."""
RAY_BATCH_WORLDS = 8
"""The most episodes one Ray task runs at once: a cluster gets many tasks, each still a batch (the
traffic alone: 16 worlds step 13x faster than one, BENCHMARKS.md)."""
PLANNING_AGENTS = ("oracle",)
"""Agents that plan on copies of the loop: they run one world at a time."""


def batch_refusal(config: RunConfig) -> str | None:
    """Why `config`'s episodes run one world at a time (one line), or None when they run as a
    batch: `sim.batched` on, the `vector` backend, the PID tracker on the kinematic plant
    (`stack.batch.closed_loop_batch.refusal`), and an agent that decides on the run's grid in the
    `observation` or `paper` encoding of features the batch computes, in one size on every road
    the episodes draw."""
    if not config.sim.batched:
        return "sim.batched is off"
    if config.sim.backend != "vector":
        return f"batched worlds are the vector backend's, not sim.backend {config.sim.backend!r}"
    refused = refusal(_alone(config))
    if refused is not None:
        return refused
    if config.planner.agent in PLANNING_AGENTS:
        return f"the {config.planner.agent} agent plans on copies of one world's loop"
    agent = kept_agent(config, config.seed)
    if agent.encoding not in ("observation", "paper"):
        return f"batched worlds encode the grid as observation or paper, not {agent.encoding!r}"
    grid = decision_grid(config, agent)
    if unbatched := [name for name in grid.features if name not in BATCHED_FEATURES]:
        return f"batched worlds do not compute the grid feature {unbatched[0]!r}"
    if len(config.highway.lane_counts) > 1 and not _one_size(grid) and isinstance(agent, BatchPolicy):
        return "roads of several lane counts give this agent observations of several sizes"
    return None


def _alone(config: RunConfig) -> RunConfig:
    """`config` without a training mix: a run drives its own world."""
    return config.model_copy(update={"train": config.train.model_copy(update={"scenarios": {}})})


def decision_grid(config: RunConfig, agent: Agent) -> GridConfig:
    """The grid `agent` decides on, as the batch encodes it: the paper state is the observation
    encoding of the grid without its features (presence, then the lane part)."""
    grid = agent.grid_config or grid_config(config)
    return grid.model_copy(update={"features": ()}) if agent.encoding == "paper" else grid


def run_batched(
    config: RunConfig,
    episodes: Sequence[int],
    on_finished: Callable[[EpisodeResult], None] | None = None,
) -> list[EpisodeResult]:
    """Episodes `episodes` of `config` (seed = config.seed + episode), one world each, stepped
    together: their results in the order given, each as `run_episode` reports it but for the grid
    snapshot and the controller's timings (none). `on_finished` sees each as its world ends."""
    seeds = [child_seed(config.seed, episode) for episode in episodes]
    worlds = len(episodes)
    loop = ClosedLoopBatch(_alone(config), worlds, metrics=True)
    results: dict[int, EpisodeResult] = {}
    try:
        loop.reset(seeds)
        agents = [kept_agent(config, seed) for seed in seeds]
        grid, with_permitted = decision_grid(config, agents[0]), sees_permitted(agents[0])
        deciding = np.ones(worlds, dtype=bool)
        since = np.zeros(worlds, dtype=np.int64)
        commands = np.full(worlds, Command.STAY.value, dtype=np.int64)
        fallback_decisions = np.zeros(worlds, dtype=np.int64)
        while len(results) < worlds:
            raise_if_stopped()
            if deciding.any():
                assert loop.perceived is not None
                seen = _seen(loop, grid, with_permitted)
                handed = decide_worlds(agents, seen, deciding, commands)
                if handed:
                    gate = agents[handed[0]]
                    assert isinstance(gate, Gate)
                    fallback = gate.fallback
                    fallback_seen = _seen(loop, decision_grid(config, fallback), sees_permitted(fallback))
                    to_fallback = np.zeros_like(deciding)
                    to_fallback[handed] = True
                    decide_worlds([fallback] * worlds, fallback_seen, to_fallback, commands)
                    fallback_decisions[handed] += 1
                loop.command(commands, deciding)
                since[deciding] = 0
            live = ~loop.done
            completed = loop.tick(live)
            since[live] += 1
            for world in np.flatnonzero(live & loop.done).tolist():
                result = loop.result(world, episodes[world], seeds[world])
                fallbacks = int(fallback_decisions[world])
                results[world] = _judged(config, replace(result, fallback_decisions=fallbacks))
                if on_finished is not None:
                    on_finished(results[world])
            deciding = ~loop.done & (completed | (~loop.changing & (since >= config.decision_ticks)))
    finally:
        loop.close()
    return [results[world] for world in range(worlds)]


def _judged(config: RunConfig, result: EpisodeResult) -> EpisodeResult:
    """`result` with its collision's fault judged as the per-world loop judges it: the batch judges
    it from the truth it keeps (`stack.fault.truth_ring`); where it could not (`fault_reason`
    empty: a world not stepped on a tick it kept), the episode is run again alone, which
    reproduces it exactly."""
    if not result.crashed or result.fault_reason:
        return result
    alone = run_episode(config, result.episode)
    return replace(result, at_fault_collision=alone.at_fault_collision, fault_reason=alone.fault_reason)


def _seen(loop: ClosedLoopBatch, grid: GridConfig, with_permitted: bool) -> np.ndarray | list[np.ndarray]:
    """Every world's observation on `grid`, followed by its permitted commands for an agent trained
    with an action mask (`with_permitted`): (worlds, values), or a list of one row a world where
    the worlds' roads have several lane counts and `grid` sizes its observation by them (each
    lane count's worlds encoded together)."""
    perceived = loop.perceived
    assert perceived is not None
    permitted = loop.permitted() if with_permitted else None
    lane_counts = np.unique(perceived.lanes_count)
    if len(lane_counts) == 1 or _one_size(grid):
        seen = observe_batch(grid, perceived)
        return seen if permitted is None else np.concatenate([seen, permitted], axis=1)
    rows: list[np.ndarray] = [np.empty(0, dtype=np.float32)] * perceived.worlds
    for lanes in lane_counts.tolist():
        worlds = np.flatnonzero(perceived.lanes_count == lanes)
        part = observe_batch(grid, perceived.rows(worlds))
        if permitted is not None:
            part = np.concatenate([part, permitted[worlds]], axis=1)
        for row, world in enumerate(worlds.tolist()):
            rows[world] = part[row]
    return rows


def _one_size(grid: GridConfig) -> bool:
    """Whether `grid`'s observation has one size on roads of any lane count."""
    return grid.lanes == "ego" and grid.lane_code == "sides"


def decide_worlds(
    agents: Sequence[Agent], seen: np.ndarray | list[np.ndarray], deciding: np.ndarray, commands: np.ndarray
) -> list[int]:
    """Each world flagged `deciding` decides on its row of `seen`: its command (a `Command` value)
    written to `commands`; one call for them all when the agents decide as a batch
    (`BatchPolicy`). Returns the worlds whose gate (`Gate`) hands the decision to its fallback."""
    worlds = np.flatnonzero(deciding)
    if isinstance(agents[0], BatchPolicy):
        assert isinstance(seen, np.ndarray), "an agent deciding as a batch sees observations of one size"
        commands[worlds] = agents[0].choose_batch(seen[worlds])
        return []
    handed = []
    for world in worlds.tolist():
        agent = agents[world]
        if isinstance(agent, Gate):
            gated = agent.gate(seen[world])
            commands[world] = int(gated.actions[0])
            if gated.handed[0]:
                handed.append(world)
        else:
            commands[world] = decide(agent, seen[world]).value
    return handed


def batches(episodes: Sequence[int], jobs: int, most: int = BATCH_WORLDS) -> list[list[int]]:
    """`episodes` split into batches of at most `most`, as even as a multiple of `jobs` batches
    makes them (every process gets as many, each as long)."""
    if not episodes:
        return []
    rounds = -(-len(episodes) // (max(jobs, 1) * most))
    count = min(len(episodes), rounds * max(jobs, 1))
    size = -(-len(episodes) // count)
    return [list(episodes[start : start + size]) for start in range(0, len(episodes), size)]
