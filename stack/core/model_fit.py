"""Whether a Q-network model can drive a road: the one check of a model file against the road it is
to drive, made by every command that takes a model (`run` and `compare` from the file's metadata
before torch is imported, every agent as built, `train.init_model`, `export`)."""

from __future__ import annotations

from pathlib import Path

from perception.grid import OccupancyGridBuilder
from planner.model_file import ModelFileError
from records import Encoding, GridConfig


def check_road_fit(
    model: Path | str,
    grid: GridConfig,
    encoding: Encoding,
    size: int,
    lanes: int | tuple[int, ...],
    option: str = "",
) -> None:
    """Refuse (ModelFileError, one line; prefixed with `option`, the setting that named the model,
    when given) a model that expects `size` observation values, seen through `grid` with
    `encoding`, on a road of `lanes` lanes (or of any of several lane counts, as random traffic
    draws them) whose grid gives another number of values."""
    for count in (lanes,) if isinstance(lanes, int) else lanes:
        given = int(OccupancyGridBuilder(grid).space(encoding, count).shape[0])
        if given != size:
            why = (
                f"{model}: expects observations of {size} values; its {encoding} grid gives {given} "
                f"on this {count}-lane road"
            )
            raise ModelFileError(f"{option}: {why}" if option else why)
