"""What a training run checks before anything is allocated: that its replay buffer, and the
demonstrations recorded beside it, fit in the memory there is (numbers only: the command that
starts the run says it, `stack.apps.training`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from stack.settings.run import RunConfig

MEMORY_SHARE = 0.8
"""The share of the available memory a run may plan to take."""


def transition_bytes(config: RunConfig) -> int:
    """Memory one stored transition takes [bytes]: its observation and next observation (float32)
    plus action, reward, done and timeout (or discount)."""
    from perception.grid import OccupancyGridBuilder
    from stack.settings.run import grid_config

    grid = OccupancyGridBuilder(grid_config(config))
    size = math.prod(grid.space(config.train.encoding, config.highway.lanes_count).shape)
    return 2 * 4 * size + 8 + 4 + 4 + 4


def replay_buffer_bytes(config: RunConfig) -> int:
    """Memory SB3's replay buffer takes for `config` [bytes]."""
    return config.train.buffer_size * transition_bytes(config)


CHECKPOINT_SLACK_BYTES = 256 * 2**20
"""What a checkpoint holds besides its transitions, at most: networks, optimizer moments, counters."""


def checkpoint_bytes(config: RunConfig) -> int:
    """Most bytes a DDQN / DQN checkpoint of `config` holds inflated: its replay buffer and
    demonstrations (a quarter more, for the columns an action mask adds) and
    `CHECKPOINT_SLACK_BYTES`; a file declaring more is not this run's, and is refused before
    anything is inflated. A tabular run's: `CHECKPOINT_BYTES`."""
    from planner.model_file import CHECKPOINT_BYTES

    if config.train.algorithm == "tabular":
        return CHECKPOINT_BYTES
    transitions = replay_buffer_bytes(config) + demonstrations_bytes(config) // 2
    return min(CHECKPOINT_BYTES, int(1.25 * transitions) + CHECKPOINT_SLACK_BYTES)


def demonstrations_bytes(config: RunConfig) -> int:
    """Memory `train.demonstrations` take at most while recorded [bytes]: every episode's decisions
    (episode length / decision period), twice (the episodes and their concatenation)."""
    if (demonstrations := config.train.demonstrations) is None:
        return 0
    decisions = math.ceil(config.highway.duration / config.decision_period_s)
    return 2 * demonstrations.episodes * decisions * transition_bytes(config)


def demonstration_rows(config: RunConfig) -> int:
    """Most transitions `train.demonstrations` can record: every episode as long as the longest
    world it is drawn from, one decision a control tick at most (0 without demonstrations)."""
    from stack.settings.run import demonstration_worlds, training_worlds

    if (demonstrations := config.train.demonstrations) is None:
        return 0
    worlds = training_worlds(demonstration_worlds(config)).values()
    ticks = max(math.ceil(world.highway.duration * world.control_rate_hz) for world in worlds)
    return demonstrations.episodes * ticks


def memory_refusal(config: RunConfig, available: int | None) -> str | None:
    """One line naming the key whose memory does not fit in `available` bytes (None: unknown),
    or None when the run fits (a tabular run keeps no buffer)."""
    if config.train.algorithm == "tabular" or available is None:
        return None
    buffer, demonstrations = replay_buffer_bytes(config), demonstrations_bytes(config)
    together = min(config.train.member_jobs, config.train.members)
    if together > 1 and (needed := together * (buffer + demonstrations)) > MEMORY_SHARE * available:
        return (
            f"train.member_jobs: {together} members at once need {needed / 2**30:.1f} GB for their "
            f"replay buffers and demonstrations; {available / 2**30:.1f} GB of memory is available"
        )
    if buffer > MEMORY_SHARE * available:
        return (
            f"train.buffer_size: {config.train.buffer_size} transitions need {buffer / 2**30:.1f} GB; "
            f"{available / 2**30:.1f} GB of memory is available"
        )
    if buffer + demonstrations > MEMORY_SHARE * available:
        episodes = config.train.demonstrations.episodes  # type: ignore[union-attr]
        return (
            f"train.demonstrations.episodes: {episodes} episodes need {demonstrations / 2**30:.1f} GB "
            f"beside the replay buffer's {buffer / 2**30:.1f} GB; {available / 2**30:.1f} GB of memory "
            "is available"
        )
    return None
