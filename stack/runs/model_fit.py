"""Whether a Q-network model can drive a road: the one check of a model file against the road it is
to drive, made by every command that takes a model (`run` and `compare` from the file's metadata
before torch is imported, every agent as built, `train.init_model` and a learned teacher's
`train.demonstrations.expert_model` before torch too, `export`)."""

from __future__ import annotations

from pathlib import Path

from perception.grid import OccupancyGridBuilder
from planner.factory import model_path
from planner.model_check import checked_model
from planner.model_file import ModelFileError
from planner.model_metadata import ModelMetadata
from planner.networks import net_arch, network_kind
from records import N_ACTIONS, Encoding, GridConfig
from stack.settings.run import RunConfig, demonstration_worlds, grid_config, training_worlds


def check_road_fit(
    model: Path | str,
    grid: GridConfig,
    encoding: Encoding,
    size: int,
    lanes: int | tuple[int, ...],
    option: str = "",
    permitted: bool = False,
) -> None:
    """Refuse (ModelFileError, one line; prefixed with `option`, the setting that named the model,
    when given) a model that expects `size` observation values, seen through `grid` with
    `encoding` (followed by the `N_ACTIONS` permitted commands when `permitted`), on a road of
    `lanes` lanes (or of any of several lane counts, as random traffic draws them) whose grid gives
    another number of values."""
    for count in (lanes,) if isinstance(lanes, int) else lanes:
        given = int(OccupancyGridBuilder(grid).space(encoding, count).shape[0]) + N_ACTIONS * permitted
        if given != size:
            why = (
                f"{model}: expects observations of {size} values; its {encoding} grid gives {given} "
                f"on this {count}-lane road"
            )
            raise ModelFileError(f"{option}: {why}" if option else why)


def check_file_fit(
    model: Path | str, metadata: ModelMetadata, lanes: int | tuple[int, ...], option: str = ""
) -> None:
    """`check_road_fit` of a Q-network model file from its `metadata`."""
    assert metadata.observation_size is not None, "a Q-network's metadata names its input size"
    size = metadata.observation_size
    check_road_fit(model, metadata.grid, metadata.encoding, size, lanes, option, metadata.action_mask)


def checked_start_model(config: RunConfig) -> Path | None:
    """The DDQN / DQN file `train.init_model` names (`shipped`: the algorithm's shipped model), None
    without one; refused (ModelFileError, one line) unless it takes this run's observations through
    this run's network on every road of the run: from the file's metadata and arrays alone, before
    torch is imported."""
    train = config.train
    if train.init_model is None:
        return None
    path = model_path(train.algorithm, None if train.init_model == "shipped" else train.init_model)
    assert path is not None, "init_model is refused for tabular runs"
    metadata = checked_model(path, ("ddqn", "dqn"))[1]
    assert metadata.observation_size is not None, "DDQN / DQN files hold Q-networks"
    if metadata.members > 1:
        raise ModelFileError(
            f"train.init_model: {path} is an ensemble of {metadata.members}; start from one member"
        )
    grid = grid_config(config)
    start_grid = metadata.grid if metadata.kind == "lane-mlp" else widened_grid(metadata.grid, grid)
    theirs = (metadata.kind, metadata.encoding, start_grid, list(metadata.hidden), metadata.action_mask)
    ours = (
        network_kind(train.network),
        train.encoding,
        grid,
        net_arch(train.network),
        train.action_mask,
    )
    fields = ("kind", "encoding", "grid", "hidden layers", "action_mask")
    for field, their, our in zip(fields, theirs, ours, strict=True):
        if their != our:
            raise ModelFileError(f"train.init_model: {path} has {field} {their}, this run needs {our}")
    lanes = config.highway.lane_counts
    check_file_fit(path, metadata, lanes, "train.init_model")
    return path


def widened_grid(start: GridConfig, grid: GridConfig) -> GridConfig:
    """`start` with `grid`'s features when it sees a subset of them (a model may start a run that
    adds features: their inputs start at zero weight), else `start` unchanged."""
    if set(start.features) <= set(grid.features):
        return start.model_copy(update={"features": grid.features})
    return start


def checked_expert_model(config: RunConfig) -> Path | None:
    """The model file of the learned expert `train.demonstrations` names (`expert_model`, by default
    its shipped file), None without one; refused (ModelFileError, one line) unless it holds that
    agent's Q-network and its grid (with the permitted commands, for a masked model) gives the
    values it expects on every road it teaches on: from the file's metadata and arrays alone,
    before torch is imported."""
    settings = config.train.demonstrations
    if settings is None or not (learned := settings.learned_experts()):
        return None
    expert = learned[0]
    path = model_path(expert, settings.expert_model)
    assert path is not None, "a learned expert has a model file"
    metadata = checked_model(path, (expert,))[1]
    worlds = training_worlds(demonstration_worlds(config))
    taught = [world for name, world in worlds.items() if settings.expert_of(name) == expert]
    lanes = tuple(sorted({count for world in taught for count in world.highway.lane_counts}))
    check_file_fit(path, metadata, lanes, "train.demonstrations.expert_model")
    return path
