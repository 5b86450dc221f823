"""The decision MDP (`HierarchicalHighway-v0`) of N worlds at once: `DecisionBatch.step(commands)`
advances every world by one decision period (`ClosedLoopBatch`) and returns the observations,
rewards and end flags the per-world env returns for each, bit for bit, with what the safety layer
and the maneuver made of each command."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from perception.grid import OccupancyGridBuilder, observe_batch
from records import N_ACTIONS, Command
from stack.batch.closed_loop_batch import ClosedLoopBatch, refusal
from stack.settings.run import RunConfig, build_config, grid_config, training_worlds
from stack.settings.train import MAX_WORLDS
from stack.training.decision_env import drawn_episode, mix_shares, with_permitted


@dataclass(frozen=True, eq=False)
class Decided:
    """One decision of every world: observations (worlds, size) float32, rewards, `terminated`
    (the ego crashed) and `truncated` (the duration ran out or the ego left the road); per world
    `permitted` (worlds, 3), the commands the loop would carry out now, and for the command given:
    `masked` (the safety layer replaced it by STAY) and `refused` (the maneuver did not start it:
    below the lane-change speed, off the road)."""

    observations: np.ndarray
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    permitted: np.ndarray
    masked: np.ndarray
    refused: np.ndarray


class BatchRefused(ValueError):
    """A valid config that the batch does not run and the per-world env does (one line)."""


def checked_worlds(worlds: object) -> int:
    """`worlds` (a vector env's `num_envs`) as an int from 1 to `MAX_WORLDS`, before anything is
    allocated for them; ValueError (one line) otherwise."""
    if isinstance(worlds, bool) or not isinstance(worlds, int | np.integer) or not 1 <= worlds <= MAX_WORLDS:
        raise ValueError(
            f"num_envs: expected a whole number of worlds from 1 to {MAX_WORLDS}, got {worlds!r:.60}"
        )
    return int(worlds)


def checked_commands(commands: object, worlds: int) -> np.ndarray:
    """`commands` as one int64 command per world: integers (not booleans, not floats, which would
    be truncated) from 0 to N_ACTIONS - 1, exactly `worlds` of them (a scalar is not broadcast);
    ValueError (one line) otherwise."""
    try:
        values = np.asarray(commands)
    except (TypeError, ValueError):
        values = np.asarray(None)
    if values.dtype.kind not in "iu" or values.ndim == 0 or values.size != worlds:
        shown = _shown(values) if values.dtype.kind != "O" else repr(commands)[:80]
        raise ValueError(
            f"actions: expected {worlds} integer commands, one per world, each 0..{N_ACTIONS - 1}, "
            f"got {shown} ({values.dtype.name}, shape {values.shape})"
        )
    values = values.reshape(worlds)
    if ((values < 0) | (values >= N_ACTIONS)).any():
        raise ValueError(
            f"actions: expected commands 0..{N_ACTIONS - 1} ({', '.join(c.name for c in Command)}), "
            f"got {_shown(values)}"
        )
    return values.astype(np.int64)


def _shown(values: np.ndarray) -> str:
    """`values` on one line, at most 80 characters."""
    return np.array2string(values, threshold=8, max_line_width=10**6)[:80]


def batch_config(config: RunConfig | dict | None) -> RunConfig:
    """`config` validated as the decision MDP's, or ValueError (one line) for what a batch does not
    run: an encoding other than `observation`, or one of another size on some road an episode
    may draw (see also `stack.batch.closed_loop_batch.refusal`)."""
    if not isinstance(config, RunConfig):
        config = build_config(config or {}, "HierarchicalHighway-v0 config")
    if config.train.encoding != "observation":
        raise BatchRefused(f"batched worlds encode train.encoding observation, not {config.train.encoding!r}")
    roads = {name: world.highway for name, world in training_worlds(config).items()}
    config.check_one_encoding(roads, "batched worlds")
    return config


class DecisionBatch:
    """`worlds` decision MDPs of one run config, stepped together; `reset(seeds)` with one traffic
    seed per world, `step(commands)`, and `reset_worlds` for the worlds whose episode ended. With a
    `train.scenarios` mix, each reset names each world's member too (`draw` draws both as the
    per-world env draws them)."""

    def __init__(self, config: RunConfig | dict | None, worlds: int) -> None:
        worlds = checked_worlds(worlds)
        self.config = config = batch_config(config)
        if (refused := refusal(config)) is not None:
            raise BatchRefused(refused)
        self.loop = ClosedLoopBatch(config, worlds)
        self.worlds = worlds
        self.grid = grid_config(config)
        self.action_mask = config.train.action_mask
        space = OccupancyGridBuilder(self.grid).space("observation", config.highway.lanes_count)
        self.observation_space: spaces.Box = with_permitted(space) if self.action_mask else space
        self.ticks = config.decision_ticks
        self.shares = mix_shares(config)

    def draw(self, generator: np.random.Generator) -> tuple[int, int]:
        """An episode's mix member and traffic seed from a world's `generator`, as
        `HierarchicalHighwayEnv` draws them from its own."""
        return drawn_episode(generator, self.shares)

    def close(self) -> None:
        self.loop.close()

    def reset(self, seeds: Sequence[int], members: Sequence[int] | None = None) -> np.ndarray:
        """Every world reset, world k with traffic seed `seeds[k]` (and mix member `members[k]`):
        the observations."""
        self.loop.reset(seeds, members)
        return self.observe()

    def reset_worlds(
        self, worlds: Sequence[int], seeds: Sequence[int], members: Sequence[int] | None = None
    ) -> None:
        """The worlds `worlds` reset, each with its traffic seed (and mix member): `observe` reads
        them after."""
        self.loop.reset_worlds(worlds, seeds, members)

    def permitted(self) -> np.ndarray:
        """(worlds, 3) float32: `ClosedLoop.permitted()` of every world."""
        return self.loop.permitted()

    def observe(self, permitted: np.ndarray | None = None) -> np.ndarray:
        """(worlds, size) float32: what the per-world env observes in each world now (`permitted`:
        `self.permitted()` when the caller already holds it)."""
        perceived = self.loop.perceived
        if perceived is None:
            raise ValueError("reset the worlds before observing them")
        encoded = observe_batch(self.grid, perceived)
        if not self.action_mask:
            return encoded
        return np.concatenate([encoded, self.permitted() if permitted is None else permitted], axis=1)

    def step(self, commands: Sequence[int] | np.ndarray, only: np.ndarray | None = None) -> Decided:
        """One decision period in every world (`HierarchicalHighwayEnv.step` of each), or in those
        flagged in `only` (the others: reward 0, no end): world k commanded `commands[k]`. Every
        world stepped must be live: reset those that ended first."""
        commands = checked_commands(commands, self.worlds)
        loop = self.loop
        acted = loop.act(commands, self.ticks, only)
        stepped = np.ones(self.worlds, dtype=bool) if only is None else np.asarray(only, dtype=bool)
        reward = self.config.train.reward
        low, high = reward.speed_range
        score = np.clip((acted.mean_speed - low) / (high - low), 0.0, 1.0)
        fraction = acted.ticks / self.ticks
        rewards = np.where(
            loop.crashed, reward.collision, fraction * (reward.alive + reward.speed_weight * score)
        )
        rewards = rewards - reward.lane_change * (acted.considered & (commands != Command.STAY))
        terminated = loop.crashed & stepped
        permitted = self.permitted()
        return Decided(
            self.observe(permitted),
            np.where(stepped, rewards, 0.0),
            terminated,
            loop.done & stepped & ~terminated,
            permitted,
            acted.masked,
            acted.refused,
        )
