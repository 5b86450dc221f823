"""The paper's network sizes by name (hidden layer widths), and the columns the lane network reads
each grid row from; no torch import, so configs load and model files are checked fast."""

from __future__ import annotations

from typing import Literal, TypeVar

import numpy as np

from records import GridConfig

NET_ARCHS: dict[str, list[int]] = {
    "shallow": [32],
    "medium": [32, 64, 32],
    "deep": [64, 128, 128, 64],
    "16": [16],
    "16x16": [16, 16],
    "lanes": [128, 64],
}
"""Hidden widths of the Q-network's MLP; for `lanes` (`LANE_NETWORK`), of its head."""
LANE_NETWORK = "lanes"
"""The network that encodes every grid row (lane) with one shared MLP before its head
(`planner.lane_network`)."""
LANE_ENCODER: tuple[int, ...] = (64, 32)
"""Widths of the shared lane encoder's layers (ReLU after each): 32 values a lane."""
ROW_PARTS = ("presence", "relative_speed", "ttc", "traffic")
"""The observation parts (`GridConfig.observation_parts`) that hold one block of values a grid row."""


def net_arch(name: str) -> list[int]:
    if name not in NET_ARCHS:
        raise ValueError(f"unknown network {name!r}; available: {', '.join(NET_ARCHS)}")
    return NET_ARCHS[name]


def lane_problem(grid: GridConfig, encoding: str) -> str | None:
    """Why the lane network cannot read this grid's observations (None: it can): it needs rows
    centred on the ego (`lanes: ego`, any road) in the `observation` encoding."""
    if encoding != "observation" or grid.lanes != "ego" or grid.lane_code != "sides":
        return "the lanes network reads the observation encoding of perception lanes: ego, lane_code: sides"
    return None


def network_kind(network: str) -> Literal["mlp", "lane-mlp"]:
    """The model file kind (`planner.model_metadata.ModelKind`) of a Q-network named `network`."""
    return "lane-mlp" if network == LANE_NETWORK else "mlp"


def lane_columns(grid: GridConfig, observation_size: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, values a row) columns of each grid row's values in an observation of `grid` (its
    presence, relative speeds, TTC and traffic, row by row), and the columns of the rest (the ego's
    own values, the lane part, and whatever follows the grid's encoding: the permitted commands)."""
    rows, parts = grid.rows(1), grid.observation_parts(1)  # lanes: ego, sides: one layout on every road
    blocks = []
    for name in ROW_PARTS:
        if name in parts:
            columns = np.arange(parts[name].start, parts[name].stop)
            blocks.append(columns.reshape(rows, -1))
    row_columns = np.concatenate(blocks, axis=1)
    rest = np.setdiff1d(np.arange(observation_size), row_columns.ravel())
    return row_columns, rest


T = TypeVar("T")

MAX_MEMBERS = 16
"""Most Q-networks an ensemble model file may hold."""


def member_prefix(index: int) -> str:
    """What the arrays of an ensemble's member `index` are named after (`member0.head.0.weight`)."""
    return f"member{index}."


def ensemble_named(members: list[dict[str, T]]) -> dict[str, T]:
    """The members' arrays (or their shapes) in one ensemble file, each named after its
    `member_prefix`."""
    return {
        member_prefix(index) + name: value
        for index, member in enumerate(members)
        for name, value in member.items()
    }


def ensemble_shapes(shapes: dict[str, tuple[int, ...]], members: int) -> dict[str, tuple[int, ...]]:
    """The arrays of `members` networks of `shapes` each (one network: `shapes` as they are)."""
    return shapes if members == 1 else ensemble_named([shapes] * members)


def mlp_shapes(sizes: list[int], prefix: str = "") -> dict[str, tuple[int, ...]]:
    """The arrays (name: shape) of SB3's MLP through layers of `sizes` (inputs first), their names
    after `prefix`."""
    shapes: dict[str, tuple[int, ...]] = {}
    for layer, (inputs, outputs) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        shapes[f"{prefix}{2 * layer}.weight"], shapes[f"{prefix}{2 * layer}.bias"] = (
            (outputs, inputs),
            (outputs,),
        )
    return shapes


def lane_network_shapes(
    grid: GridConfig, observation_size: int, head: list[int], actions: int
) -> dict[str, tuple[int, ...]]:
    """The arrays (name: shape) a lane network of `head` widths holds (`planner.lane_network`)."""
    row_columns, rest = lane_columns(grid, observation_size)
    encoder = mlp_shapes([row_columns.shape[1], *LANE_ENCODER], "features.encoder.")
    inputs = row_columns.shape[0] * LANE_ENCODER[-1] + rest.size
    return encoder | mlp_shapes([inputs, *head, actions], "head.")
