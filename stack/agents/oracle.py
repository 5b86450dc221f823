"""The `oracle` agent: a perfect-information planner, each scenario's ceiling for the decision layer.

At a decision point it copies the whole closed loop (simulator, traffic, sensor, safety layer,
maneuver, controllers: the simulator is deterministic once spawned, so a copy foresees the other
vehicles exactly) and searches a tree of `depth` consecutive decisions: every command the safety
layer lets through, then every command at the next decision point, and so on; each leaf is
followed by the `base` agent until `horizon_s` after the root. A branch is worth the distance the
ego gains along the road by then (minus infinity on a crash); a lane change must gain `margin_m`
more than staying. With the shipped Double DQN as `base` (the default) the rollouts drive the best
agent there is and the tree adds what changing its next decisions gains with the future known: a
reference ceiling for any agent on the same seeds, controllers and safety layer, though not an
exhaustive optimum. It costs up to 3^depth look-ahead rollouts per decision (the cost per episode
is in BENCHMARKS.md). Where the loop copies into a batch of worlds (the `vector` backend's highway
road, the PID tracker on the kinematic plant, no sensor model: `stack.batch.loop_copies`), the
3^depth command paths are played as one batch, stepped together (`stack.agents.oracle_search`;
about 3x cheaper an episode). Elsewhere they are forks of the loop played one at a time, fewer
where a search goes on from the last one: its leaves are kept, and when the loop then stands where
one of its root commands led (the same world, bit for bit: the simulator is deterministic), a leaf
of the new search whose commands are a kept leaf's after the first (its base agent's first command
included) is that same future, played on only for the time the root moved on. Either way every
value, so every decision, is the one a search from scratch on forks makes.

It is an agent, one of `drivestack agents`, but it lives here, beside the closed loop, rather than
in `planner/` with the others: it plans on the loop itself (`ClosedLoop.fork`, `permits`,
`changing_lane`), and the layers never import `stack`. The loop knows it only as an agent with a
`plan(loop)` (`stack.runs.alone.agent_step`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from perception.grid import OccupancyGridBuilder
from planner.agents import Action, Agent, Policy, decide, sees_permitted
from planner.factory import make_agent
from records import Command, Encoding, GridConfig, WorldState
from stack.agents.oracle_search import COMMANDS, BatchedSearch, search_refusal
from stack.loop.closed_loop import ClosedLoop
from stack.settings.layers import OracleConfig
from stack.sim.batch.world_reading import UnsupportedRoad

Path = tuple[Command, ...]
"""Commands given from a search's root."""


@dataclass
class Leaf:
    """A rollout where it stopped (`horizon_s` after its search's root, or its episode's end) and
    every command that led there from the root: the tree's, then the base agent's."""

    loop: ClosedLoop
    commands: list[Command]


class Oracle(Policy):
    """`plan(loop)` searches copies of `loop`; `predict` is refused (it needs the simulator)."""

    encoding: Encoding = "paper"

    def __init__(self, config: OracleConfig, base: Agent) -> None:
        """The rollouts perceive as `base` does: on its own grid, if it has one."""
        self.config = config
        self.base = base
        self.grid_config: GridConfig | None = base.grid_config
        self.view = OccupancyGridBuilder(base.grid_config) if base.grid_config is not None else None
        self.values = np.full(len(COMMANDS), np.nan)
        self._leaves: list[Leaf] = []
        self._reached: dict[Command, tuple[WorldState, bool]] = {}
        self._kept: dict[Path, Leaf] = {}
        self._search: BatchedSearch | None = None

    @classmethod
    def for_road(cls, config: OracleConfig, lanes: int, grid: GridConfig) -> Oracle:
        """The oracle whose base policy is `config.base` as built for this road; a learned base
        decides on its network's own argmax (no change margin), as when the ceilings were measured."""
        return cls(config, make_agent(config.base, lanes, grid, change_margin=0.0))

    score_name = "distance reached [m] (lane changes less the margin)"

    def scores(self, observation: np.ndarray) -> np.ndarray:
        """What the last `plan` rated each `Command` (NaN before the first, or when no lane change
        was permitted and nothing was searched); `observation` is not read."""
        return self.values.copy()

    def choose(self, observation: np.ndarray) -> Action:
        raise TypeError("the oracle plans on copies of the simulator: call plan(loop), not predict")

    def plan(self, loop: ClosedLoop) -> Command:
        """The root command whose best branch gets furthest without a crash."""
        start_s, start_time = float(loop.world.s[0]), loop.world.time
        self.values = np.full(len(COMMANDS), np.nan)
        self._kept = self._continued(loop)
        self._leaves, self._reached = [], {}
        if not any(loop.permits(c) for c in COMMANDS[1:]):
            return Command.STAY
        values = self._batched_values(loop, start_s, start_time)
        if values is None:
            values = [
                self._value(loop, command, self.config.depth, start_s, start_time) for command in COMMANDS
            ]
        values[1:] = [value - self.config.margin_m for value in values[1:]]
        for command, value in zip(COMMANDS, values, strict=True):
            self.values[command] = value
        self._kept = {}
        return COMMANDS[int(np.argmax(values))]

    def _batched_values(self, loop: ClosedLoop, start_s: float, start_time: float) -> list[float] | None:
        """The root commands' values from the tree played as one batch of worlds
        (`stack.agents.oracle_search`), or None where the loop cannot be copied into one."""
        if search_refusal(loop, self.base) is not None:
            return None
        if self._search is None or self._search.run is not loop.config:
            if self._search is not None:
                self._search.close()
            self._search = BatchedSearch(self.config, self.base, loop.config)
        roots = [loop.changing_lane or loop.permits(command) for command in COMMANDS]
        try:
            return self._search.values(loop, roots, start_s, start_time)
        except UnsupportedRoad:
            return None

    def _continued(self, loop: ClosedLoop) -> dict[Path, Leaf]:
        """The last search's leaves that go on from `loop`, by their tree's commands from it: those
        under the root command whose copy reached the world `loop` stands in now, bit for bit, with a
        lane change running there as here or in neither."""
        depth = self.config.depth
        kept: dict[Path, Leaf] = {}
        for command, (reached, changing) in self._reached.items():
            if changing != loop.changing_lane or not _same_world(loop.world, reached):
                continue
            for leaf in self._leaves:
                if leaf.commands[0] == command and len(leaf.commands) > depth:
                    kept[tuple(leaf.commands[1 : depth + 1])] = leaf
        return kept

    def _value(
        self,
        loop: ClosedLoop,
        command: Command,
        depth: int,
        start_s: float,
        start_time: float,
        path: Path = (),
    ) -> float:
        """Best distance [m] from `start_s` after `command` and `depth - 1` more decisions; a
        command the safety layer would mask is worth nothing, decided before anything is copied.
        `path`: the commands from the root before `command`."""
        if not loop.changing_lane and not loop.permits(command):
            return -math.inf
        path = (*path, command)
        kept = self._kept.pop(path, None) if depth == 1 else None
        if kept is not None:
            return self._leaf_value(Leaf(kept.loop, kept.commands[1:]), start_s, start_time)
        future = loop.fork(self.view)
        future.act(command)
        if len(path) == 1:
            self._reached[path[0]] = (future.world, future.changing_lane)
        if future.crashed:
            return -math.inf
        if depth > 1 and not future.done:
            future.perceive()
            return max(
                self._value(future, next_command, depth - 1, start_s, start_time, path)
                for next_command in COMMANDS
            )
        return self._leaf_value(Leaf(future, list(path)), start_s, start_time)

    def _leaf_value(self, leaf: Leaf, start_s: float, start_time: float) -> float:
        """The distance [m] from `start_s` the base agent drives `leaf` to by `horizon_s` after
        `start_time` (minus infinity on a crash); the leaf is kept with the commands it was given."""
        self._leaves.append(leaf)
        future = leaf.loop
        while not future.done and future.world.time - start_time < self.config.horizon_s:
            grid = future.perceive()
            seen = future.observation(grid, self.base.encoding, sees_permitted(self.base))
            command = decide(self.base, seen)
            leaf.commands.append(command)
            future.act(command)
        return -math.inf if future.crashed else float(future.world.s[0]) - start_s


def _same_world(world: WorldState, other: WorldState) -> bool:
    """Whether two snapshots hold the same vehicles at the same time, bit for bit (the lanes, one
    road's geometry, left out)."""
    if world is other:
        return True
    for field in fields(world):
        if field.name == "lanes":
            continue
        mine, theirs = getattr(world, field.name), getattr(other, field.name)
        if isinstance(mine, np.ndarray):
            if mine.shape != theirs.shape or mine.dtype != theirs.dtype or not np.array_equal(mine, theirs):
                return False
        elif mine != theirs:
            return False
    return True
