"""The oracle's search with every branch a world of one batch: `BatchedSearch.values` plays the
3^depth command paths of the oracle's tree (`stack.agents.oracle`) from copies of the loop
(`stack.batch.loop_copies.copy_loop`), every path a world of a `ClosedLoopBatch` stepped together,
the tree's commands given at each world's decision points and the base agent deciding after them
until `horizon_s` past the root. Each world is the fork `Oracle._value` plays that path on, bit for
bit, so each branch is worth what it is worth there, and the root's values are the per-world
search's: the same decisions. A path whose first commands end the episode, or whose command the
safety layer masks, stops there, as that search's branch does (its siblings share its value)."""

from __future__ import annotations

import itertools
import math

import numpy as np

from perception.grid import BATCHED_FEATURES, observe_batch
from planner.agents import Agent, BatchPolicy, decide, sees_permitted
from planner.safety import permitted_batch
from records import Command, GridConfig
from stack.batch.closed_loop_batch import ClosedLoopBatch
from stack.batch.loop_copies import copy_loop, copy_refusal
from stack.loop.closed_loop import ClosedLoop, grid_config
from stack.settings.layers import OracleConfig
from stack.settings.run import RunConfig

COMMANDS = (Command.STAY, Command.LEFT, Command.RIGHT)
"""The tree's commands, in the order the oracle rates them."""


def search_refusal(loop: ClosedLoop, base: Agent) -> str | None:
    """Why the oracle's rollouts of `loop` for `base` run as forks one at a time (one line), or
    None when they run as a batch: the loop copies into a batch (`copy_refusal`) and `base`
    decides on an encoding of the grid the batch computes."""
    refused = copy_refusal(loop)
    if refused is not None:
        return refused
    if base.encoding not in ("observation", "paper"):
        return f"batched rollouts encode the grid as observation or paper, not {base.encoding!r}"
    grid = base_grid(loop.config, base)
    if any(name not in BATCHED_FEATURES for name in grid.features):
        return "batched rollouts do not compute every grid feature the base agent reads"
    return None


def base_grid(config: RunConfig, base: Agent) -> GridConfig:
    """The grid `base` decides on, as the batch encodes it (the paper state is the observation
    encoding of the grid without its features)."""
    grid = base.grid_config or grid_config(config)
    return grid.model_copy(update={"features": ()}) if base.encoding == "paper" else grid


class BatchedSearch:
    """The oracle's tree of `config.depth` decisions over `base`, on a batch of 3^depth worlds of
    `run` made once and loaded anew at every search."""

    def __init__(self, config: OracleConfig, base: Agent, run: RunConfig) -> None:
        self.config, self.base, self.run = config, base, run
        self.paths = np.array(list(itertools.product(range(len(COMMANDS)), repeat=config.depth)))
        """(worlds, depth): each world's tree commands, as indices of `COMMANDS`."""
        self.worlds = len(self.paths)
        self.batch = ClosedLoopBatch(run, self.worlds)
        self.grid = base_grid(run, base)

    def close(self) -> None:
        self.batch.close()

    def values(self, loop: ClosedLoop, roots: list[bool], start_s: float, start_time: float) -> list[float]:
        """Per root command (`COMMANDS` order), the distance [m] from `start_s` its best path
        reaches by `horizon_s` after `start_time` (minus infinity on a crash, or where `roots` says
        the safety layer masks the root command)."""
        batch, paths, worlds = self.batch, self.paths, self.worlds
        copy_loop(batch, range(worlds), loop)
        reached = np.full(worlds, -math.inf)
        active = np.array([roots[first] for first in paths[:, 0]])
        stage = np.zeros(worlds, dtype=np.int64)
        since = np.zeros(worlds, dtype=np.int64)
        commands = np.full(worlds, Command.STAY.value, dtype=np.int64)
        tree_commands = np.array([command.value for command in COMMANDS])[paths]
        deciding = active.copy()
        depth, horizon = self.config.depth, self.config.horizon_s
        while active.any():
            if deciding.any():
                ended = deciding & batch.done
                if stage.max() >= depth:
                    ended |= deciding & (stage >= depth) & (batch.traffic.time - start_time >= horizon)
                self._finish(ended, reached, active, start_s)
                deciding &= ~ended
                in_tree = deciding & (stage < depth)
                next_command = tree_commands[np.arange(worlds), np.minimum(stage, depth - 1)]
                checked = in_tree & (stage >= 1) & ~batch.changing
                if checked.any():
                    masked = checked & ~self._permits(next_command)
                    active &= ~masked
                    deciding &= ~masked
                    in_tree &= ~masked
                commands[in_tree] = next_command[in_tree]
                self._base_decides(deciding & (stage >= depth), commands)
                batch.command(commands, deciding)
                stage[deciding] += 1
                since[deciding] = 0
            if not active.any():
                break
            completed = batch.tick(active)
            since[active] += 1
            decision_point = completed | (~batch.changing & (since >= self.run.decision_ticks))
            deciding = active & (batch.done | decision_point)
        return [float(reached[paths[:, 0] == root].max()) for root in range(len(COMMANDS))]

    def _finish(self, ended: np.ndarray, reached: np.ndarray, active: np.ndarray, start_s: float) -> None:
        """The worlds flagged `ended` stop: each worth the distance its ego drove from `start_s`,
        minus infinity on a crash."""
        if not ended.any():
            return
        truth = self.batch.batch
        assert truth is not None
        driven = truth.s[:, 0] - start_s
        reached[ended] = np.where(self.batch.crashed[ended], -math.inf, driven[ended])
        active &= ~ended

    def _permits(self, commands: np.ndarray) -> np.ndarray:
        """Per world, whether the safety layer passes its command `commands` (values) now, at any
        speed (`ClosedLoop.permits`)."""
        batch = self.batch
        assert batch.perceived is not None and batch.batch is not None
        safety, speed = self.run.planner.safety, batch.batch.speed[:, 0]
        permitted = permitted_batch(safety, batch.perceived, batch.lane, batch.changing, speed, -math.inf)
        return permitted[np.arange(self.worlds), commands] == 1.0

    def _base_decides(self, deciding: np.ndarray, commands: np.ndarray) -> None:
        """The base agent's command in each world flagged `deciding`, on its view of what that
        world's ego perceives (as `Oracle._leaf_value` shows it to the agent)."""
        if not deciding.any():
            return
        batch = self.batch
        assert batch.perceived is not None
        seen = observe_batch(self.grid, batch.perceived)
        if sees_permitted(self.base):
            seen = np.concatenate([seen, batch.permitted()], axis=1)
        rows = np.flatnonzero(deciding)
        if isinstance(self.base, BatchPolicy):
            commands[rows] = self.base.choose_batch(seen[rows])
            return
        for row in rows.tolist():
            commands[row] = decide(self.base, seen[row]).value
