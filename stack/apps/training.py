"""What `drivestack train` checks before any work (the replay buffer fits in memory, a checkpoint
to resume is one) and prints after."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from stack.apps.options import fail

if TYPE_CHECKING:
    from stack.core.config import RunConfig


def transition_bytes(config: RunConfig) -> int:
    """Memory one stored transition takes [bytes]: its observation and next observation (float32)
    plus action, reward, done and timeout (or discount)."""
    from perception.grid import OccupancyGridBuilder
    from stack.core.config import grid_config

    grid = OccupancyGridBuilder(grid_config(config))
    size = math.prod(grid.space(config.train.encoding, config.highway.lanes_count).shape)
    return 2 * 4 * size + 8 + 4 + 4 + 4


def replay_buffer_bytes(config: RunConfig) -> int:
    """Memory SB3's replay buffer takes for `config` [bytes]."""
    return config.train.buffer_size * transition_bytes(config)


def demonstrations_bytes(config: RunConfig) -> int:
    """Memory `train.demonstrations` take at most while recorded [bytes]: every episode's decisions
    (episode length / decision period), twice (the episodes and their concatenation)."""
    if (demonstrations := config.train.demonstrations) is None:
        return 0
    decisions = math.ceil(config.highway.duration / config.decision_period_s)
    return 2 * demonstrations.episodes * decisions * transition_bytes(config)


def available_memory_bytes() -> int | None:
    """MemAvailable of /proc/meminfo [bytes]; None where it cannot be read."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_memory(config: RunConfig) -> None:
    """Refuse, before anything is allocated, a replay buffer (with the demonstrations) that does not
    fit in memory."""
    available = available_memory_bytes()
    if config.train.algorithm == "tabular" or available is None:
        return
    buffer, demonstrations = replay_buffer_bytes(config), demonstrations_bytes(config)
    if buffer > 0.8 * available:
        fail(
            f"train.buffer_size: {config.train.buffer_size} transitions need {buffer / 2**30:.1f} GB; "
            f"{available / 2**30:.1f} GB of memory is available"
        )
    if buffer + demonstrations > 0.8 * available:
        episodes = config.train.demonstrations.episodes  # type: ignore[union-attr]
        fail(
            f"train.demonstrations.episodes: {episodes} episodes need {demonstrations / 2**30:.1f} GB "
            f"beside the replay buffer's {buffer / 2**30:.1f} GB; {available / 2**30:.1f} GB of memory "
            "is available"
        )


def check_init_model(config: RunConfig) -> None:
    """Refuse, before the run folder exists, a `train.init_model` that does not fit the run (torch
    and SB3 are imported only when there is one to check)."""
    if config.train.init_model is None:
        return
    from planner.model_file import ModelFileError
    from stack.apps.train_model import initial_model

    try:
        initial_model(config)
    except ModelFileError as error:
        fail(str(error))


def train_or_fail(config: RunConfig, folder: Path, progress: bool) -> bool:
    """`drivestack train` in `folder`; a checkpoint that cannot be resumed is a one-line error.
    True when interrupted (resumable)."""
    from planner.model_file import CHECKPOINT, ModelFileError, load_checkpoint

    try:
        if (checkpoint := folder / CHECKPOINT).is_file():
            load_checkpoint(checkpoint, arrays=False)
        return train_and_report(config, folder, progress)
    except ModelFileError as error:
        fail(str(error))


def train_and_report(config: RunConfig, folder: Path, progress: bool) -> bool:
    """Train (or resume) in `folder` and print the outcome; True when interrupted (resumable)."""
    from stack.apps.train import Trainer

    summary = Trainer(config, folder, progress=progress).run()
    best, interrupted = summary["best_validation"], bool(summary["interrupted"])
    found = (
        "no validation yet"
        if not best
        else (
            f"best validation at step {best['step']}: collision rate {best['collision_rate']:.1%}, "
            f"mean return {best['mean_return']:.2f}, mean speed {best['mean_speed']:.2f} m/s"
        )
    )
    print(f"{summary['algorithm']}: {summary['steps']} steps in {summary['wall_time_s']:.0f} s; {found}")
    print(f"run folder: {folder}" + (" (interrupted: resume with --resume)" if interrupted else ""))
    return interrupted
