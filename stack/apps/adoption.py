"""`train --resume DIR --adopt`: a training folder made before results folders recorded their owner
(`stack.runtime.owner.MARKER`) is taken over only when asked, and only when its `config.yaml` agrees
with what the run's own files recorded: the files are a training run's, its model files were
trained with this algorithm, encoding, network, grid, lane count and seed, its checkpoint with this
learning rate, its summary with this algorithm and network. What no file records (gamma, the
reward) the user vouches for by asking."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from planner.model_file import CHECKPOINT, ModelFileError, load_checkpoint, load_model
from stack.runtime.owner import LOCK

if TYPE_CHECKING:
    from stack.settings.run import RunConfig

MODELS = ("best.npz", "final.npz")
TRAINING_FILES = frozenset(
    {
        "config.yaml",
        CHECKPOINT,
        *MODELS,
        "summary.json",
        "validation.json",
        "training_curve.png",
        "tensorboard",
        LOCK,
    }
)
"""Everything a training run folder holds (besides temporary files a killed writer left)."""


def adoption_refusal(folder: Path, config: RunConfig) -> str | None:
    """Why `folder`, a training folder without an owner record, may not be adopted for `config`
    (its own config.yaml) in one line; None when every file the run wrote agrees."""
    strangers = sorted(
        p.name for p in folder.iterdir() if p.name not in TRAINING_FILES and ".partial" not in p.name
    )
    if strangers:
        return (
            f"--adopt: {folder} holds {strangers[0]}, which no training run writes; not a training run folder"
        )
    try:
        settings = recorded_settings(folder, config)
    except ModelFileError as error:
        return f"--adopt: {error}"
    for name, recorded, expected in settings:
        if recorded != expected:
            return (
                f"--adopt: {folder / name} was trained with {recorded!r}, but config.yaml says {expected!r}: "
                "config.yaml was changed after the run started; put it back or train afresh"
            )
    return None


def recorded_settings(folder: Path, config: RunConfig) -> list[tuple[str, Any, Any]]:
    """(file and key, what the file recorded, what `config` gives) for every setting the run's
    files recorded; ModelFileError for a model file or checkpoint that cannot be read."""
    from stack.settings.run import grid_config

    train = config.train
    expected = {
        "algorithm": train.algorithm,
        "encoding": train.encoding,
        "network": train.network,
        "grid": grid_config(config).model_dump(mode="json"),
        "lanes_count": config.highway.lanes_count,
        "seed": config.seed,
    }
    found: list[tuple[str, Any, Any]] = []
    for name in MODELS:
        if (folder / name).is_file():
            _, metadata = load_model(folder / name, arrays=False)
            found += [(f"{name} {key}", metadata.get(key), value) for key, value in expected.items()]
    if train.algorithm != "tabular":
        _, metadata = load_checkpoint(folder / CHECKPOINT, arrays=False)
        groups = metadata["counters"].get("param_groups") or [{}]
        found.append((f"{CHECKPOINT} learning rate", groups[0].get("lr"), train.learning_rate))
    if (folder / "summary.json").is_file():
        summary = _summary(folder / "summary.json")
        found += [
            (f"summary.json {key}", summary.get(key), expected[key]) for key in ("algorithm", "network")
        ]
    return found


def _summary(path: Path) -> dict[str, Any]:
    try:
        summary = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        return {}
    return summary if isinstance(summary, dict) else {}
