"""The agent protocol (SB3's `predict`, plus what the loop must show the agent) and the
hand-written agents.

An agent maps an observation, the perception encoding named by its `encoding`, of the grid its
`grid_config` describes (None: the run's grid), to an action index of `Command`. The loop reads
those two attributes to build what the agent sees, so it never knows which agent it has.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from records import MAX_LANES, N_ACTIONS, Command, Encoding, GridConfig

Action = np.ndarray | np.integer
"""An action index of `Command`, or one per row of a batch of observations."""
Prediction = tuple[Action, Any]
"""What `predict` returns, as SB3's: (action, recurrent state)."""


@runtime_checkable
class Agent(Protocol):
    @property
    def encoding(self) -> Encoding: ...

    @property
    def grid_config(self) -> GridConfig | None: ...

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> Prediction: ...


@runtime_checkable
class Scored(Protocol):
    """An agent that can say how it rated each command of a decision (a recording shows it):
    `scores(observation)` gives one value per `Command` (NaN where a command was not rated), in
    the unit `score_name` names."""

    score_name: str

    def scores(self, observation: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Gated:
    """One gated decision per row: the ensemble's commands, their disagreement and coefficient of
    variation, and which rows go to the fallback."""

    actions: np.ndarray
    disagreement: np.ndarray
    variation: np.ndarray
    handed: np.ndarray


@runtime_checkable
class Gate(Protocol):
    """An agent that hands a decision to its `fallback` where `gate` says so
    (`planner.uncertainty.GatedAgent`): the loop then shows the fallback its own view."""

    fallback: Agent
    fallback_name: str
    threshold: float

    def gate(self, observation: np.ndarray) -> Gated: ...


@runtime_checkable
class BatchPolicy(Protocol):
    """An agent that decides for many worlds in one call: `choose_batch(observations)` gives, per
    row of `observations` (worlds, size), the `Command` value `predict` gives on that row alone.
    Its decisions depend on the observation only (not on the seed it was built with), so one of
    them decides for every world of a batch."""

    def choose_batch(self, observations: np.ndarray) -> np.ndarray: ...


def sees_permitted(agent: object) -> bool:
    """Whether the loop shows `agent` the safety layer's permitted commands after its encoding
    (`N_ACTIONS` values, 1 permitted, 0 refused, in `Command` order): an agent trained with an
    action mask says so with `sees_permitted = True` (any agent may; by default none does)."""
    return getattr(agent, "sees_permitted", False) is True


def decide(agent: Agent, observation: np.ndarray) -> Command:
    """One greedy decision."""
    action, _ = agent.predict(observation, deterministic=True)
    return Command(int(np.asarray(action).reshape(-1)[0]))


class Policy:
    """Base of the agents that decide on an observation alone: SB3's `predict` over `choose`
    (greedy; no recurrent state, which is handed back unchanged). By default they read the paper
    state of the run's grid."""

    encoding: Encoding = "paper"
    grid_config: GridConfig | None = None

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> Prediction:
        return self.choose(observation), state

    def choose(self, observation: np.ndarray) -> Action:
        raise NotImplementedError


class KeepLaneAgent(Policy):
    """Never changes lane: the lower bound every other agent should beat on speed."""

    def choose(self, observation: np.ndarray) -> Action:
        return np.array(Command.STAY)


class RandomAgent(Policy):
    """Uniformly random commands from its own seeded generator."""

    def __init__(self, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)

    def choose(self, observation: np.ndarray) -> Action:
        return np.array(self.rng.integers(0, N_ACTIONS))


class FreeGapAgent(Policy):
    """Rule baseline on the paper state: when a car is in sight in the own lane, move to the
    adjacent lane with the most free cells ahead, only if it is strictly freer and its gap around
    the ego (from `safe_cells_behind` behind to `safe_cells_ahead` ahead) is empty."""

    def __init__(
        self, lanes: int, grid: GridConfig, safe_cells_behind: int = 3, safe_cells_ahead: int = 2
    ) -> None:
        self.lanes = lanes
        self.grid = grid
        self.safe_cells_behind = min(safe_cells_behind, grid.cells_behind)
        self.safe_cells_ahead = safe_cells_ahead

    def _decode(self, observation: np.ndarray) -> tuple[np.ndarray, int]:
        """(presence grid, ego row) from a paper state."""
        observation = np.asarray(observation).reshape(-1)
        rows = self.grid.rows(self._lanes_seen(observation.size))
        size = rows * self.grid.cells
        if self.grid.lanes == "absolute":
            bits = observation[size:].astype(int)
            ego_row = int(sum(bit << (len(bits) - 1 - i) for i, bit in enumerate(bits)))
        else:
            ego_row = self.grid.lateral_reach
        return observation[:size].reshape(rows, self.grid.cells), ego_row

    def _lanes_seen(self, size: int) -> int:
        """The lane count of the road a paper state of `size` values shows (with absolute rows it
        varies from road to road, e.g. in the `random` scenario); ValueError if none fits."""
        for lanes in (self.lanes, *range(1, MAX_LANES + 1)):
            if self.grid.rows(lanes) * self.grid.cells + self.grid.lane_code_size(lanes) == size:
                return lanes
        rows = self.grid.rows(self.lanes)
        expected = rows * self.grid.cells + self.grid.lane_code_size(self.lanes)
        raise ValueError(
            f"rule agent expected a paper state of {expected} values "
            f"({rows} rows x {self.grid.cells} cells + lane code), got {size}"
        )

    def free_cells(self, cells: np.ndarray) -> np.ndarray:
        """Per lane, free cells ahead of the ego's column (cells_ahead when all clear)."""
        ahead = cells[:, self.grid.ego_column + 1 :] > 0
        if ahead.shape[1] == 0:
            return np.full(cells.shape[0], self.grid.cells_ahead)
        return np.where(ahead.any(axis=1), np.argmax(ahead, axis=1), self.grid.cells_ahead)

    def gap_is_safe(self, cells: np.ndarray, row: int) -> bool:
        """Row `row` exists and is empty around the ego (lanes off the road are marked full)."""
        low = self.grid.ego_column - self.safe_cells_behind
        high = self.grid.ego_column + self.safe_cells_ahead
        return 0 <= row < cells.shape[0] and not cells[row, low : high + 1].any()

    def choose(self, observation: np.ndarray) -> Action:
        cells, ego_row = self._decode(observation)
        free = self.free_cells(cells)
        if free[ego_row] >= self.grid.cells_ahead:
            return np.array(Command.STAY)
        best, best_free = Command.STAY, free[ego_row]
        for command in (Command.LEFT, Command.RIGHT):
            row = ego_row + command.lane_shift
            if self.gap_is_safe(cells, row) and free[row] > best_free:
                best, best_free = command, free[row]
        return np.array(best)
