"""`drivestack/HierarchicalHighway-v0`: the decision layer's MDP on the full stack.

Action: `Discrete(3)` (LEFT, STAY, RIGHT). Observation: the perception encoding named by
`config.train.encoding`, followed with `train.action_mask` by the safety layer's permitted commands
(`ClosedLoop.permitted`: 3 values, 1 permitted, 0 refused). One step is one decision period of the
closed loop: the safety layer, maneuver and controllers run inside at the control rate. A lane
change spans several steps, and actions taken while it runs are ignored, so every transition lasts
the same time (one discount factor per step is then right; a whole lane change in one step would
earn several periods of reward for one discount and bias the agent towards changing lane). Reward:
see `RewardConfig` (the paper's +1 / -1 by default). With `train.scenarios`, each episode draws its
world from the mix (one closed loop per scenario, all shown the same encoding, which must then have
one size on every road).
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from perception.grid import OccupancyGridBuilder
from records import N_ACTIONS, TRAINING_SEED_FLOOR, Command, drawn_seed
from stack.loop.closed_loop import ClosedLoop
from stack.settings.run import RunConfig, build_config, grid_config, training_worlds
from stack.sim.highway import HighwayAdapter


@dataclass
class EpisodeRecord:
    """An episode of the decision MDP as plain data: the env generator's state when it began (it
    draws the world and the traffic seed) and the actions taken since (`Command` values)."""

    generator_state: dict
    actions: list[int]


def with_permitted(space: spaces.Box) -> spaces.Box:
    """`space` followed by the `N_ACTIONS` permitted-command values, each in [0, 1]."""
    low, high = np.zeros(N_ACTIONS, space.dtype), np.ones(N_ACTIONS, space.dtype)
    return spaces.Box(np.concatenate([space.low, low]), np.concatenate([space.high, high]))


def mix_shares(config: RunConfig) -> np.ndarray:
    """The chance an episode is each world of `training_worlds(config)` (its `train.scenarios`
    weights normalised; one world: 1)."""
    mix = config.train.scenarios
    return np.array(list(mix.values()) if mix else [1.0]) / sum(mix.values() or [1.0])


def drawn_episode(rng: np.random.Generator, shares: np.ndarray) -> tuple[int, int]:
    """An episode's world (an index of `shares`) and traffic seed, drawn from `rng` in this order."""
    world = int(rng.choice(len(shares), p=shares)) if len(shares) > 1 else 0
    return world, drawn_seed(rng, TRAINING_SEED_FLOOR)


class HierarchicalHighwayEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"]}
    observation_space: spaces.Box

    def __init__(self, config: RunConfig | dict | None = None, render_mode: str | None = None) -> None:
        super().__init__()
        if not isinstance(config, RunConfig):
            config = build_config(config or {}, "HierarchicalHighway-v0 config")
        self.config = config
        self.render_mode = render_mode
        worlds = training_worlds(config)
        self.worlds, self.world_names = list(worlds.values()), list(worlds)
        self.shares = mix_shares(config)
        self.adapters = [
            HighwayAdapter(
                world.highway, world.sim.backend, render=render_mode == "rgb_array", plant=world.sim.plant
            )
            for world in self.worlds
        ]
        self.loops = [
            ClosedLoop(world, adapter) for world, adapter in zip(self.worlds, self.adapters, strict=True)
        ]
        self.adapter, self.loop = self.adapters[0], self.loops[0]
        self.encoding = config.train.encoding
        builder = OccupancyGridBuilder(grid_config(self.worlds[0]))
        space = builder.space(self.encoding, config.highway.lanes_count)
        self.action_mask = config.train.action_mask
        self.observation_space = with_permitted(space) if self.action_mask else space
        self.action_space = spaces.Discrete(N_ACTIONS)

    def _observe(self) -> np.ndarray:
        return self.loop.observation(self.loop.perceive(), self.encoding, self.action_mask)

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict[str, float | int | bool]]:
        super().reset(seed=seed)
        self._begin_episode(dict(self.np_random.bit_generator.state))
        return self._observe(), self.loop.status().info()

    def _begin_episode(self, generator_state: dict) -> None:
        self.episode = EpisodeRecord(generator_state, [])
        world, seed = drawn_episode(self.np_random, self.shares)
        self.adapter, self.loop = self.adapters[world], self.loops[world]
        self.world_name = self.world_names[world]
        self.loop.reset(seed)

    def episode_record(self) -> EpisodeRecord:
        """The episode under way as data (for a checkpoint)."""
        return EpisodeRecord(dict(self.episode.generator_state), list(self.episode.actions))

    def replay_episode(self, record: EpisodeRecord) -> np.ndarray:
        """Rebuild the episode `record` describes and return its current observation: the
        generator is put back where the episode began, which draws the same world and seed, and the
        same actions drive the deterministic loop to the same state."""
        self.np_random.bit_generator.state = record.generator_state
        self._begin_episode(record.generator_state)
        for action in record.actions:
            if self.loop.done:
                break
            self.step(action)
        return self._observe()

    def step(
        self, action: int | np.integer | np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, float | int | bool]]:
        command = Command(int(action))
        self.episode.actions.append(command.value)
        acted = self.loop.act(command, ticks=self.config.decision_ticks)
        reward_config = self.config.train.reward
        if self.loop.crashed:
            reward = reward_config.collision
        else:
            fraction = acted.ticks / self.config.decision_ticks
            low, high = reward_config.speed_range
            speed_score = float(np.clip((acted.mean_speed - low) / (high - low), 0.0, 1.0))
            reward = fraction * (reward_config.alive + reward_config.speed_weight * speed_score)
        reward -= reward_config.lane_change * (acted.considered and command is not Command.STAY)

        terminated = self.loop.crashed
        truncated = self.loop.done and not terminated
        return self._observe(), float(reward), terminated, truncated, self.loop.status().info()

    def render(self) -> np.ndarray | None:
        return self.adapter.render() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        for adapter in self.adapters:
            adapter.close()
