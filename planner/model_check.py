"""What a model file must hold before an agent is built from it, checked with numpy alone (no
torch import, so a bad file is refused in a fraction of a second): the kind, algorithm, encoding,
grid and action count the loop can use, network sizes within bounds, the arrays' shapes equal to
the ones those sizes give, every weight finite."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from planner.mobil import prior_problem
from planner.model_file import ModelFileError, load_model
from planner.model_metadata import GATE_MEASURES, MAX_CHANGE_MARGIN, ModelMetadata, whole_number
from planner.networks import MAX_MEMBERS, ensemble_shapes, lane_network_shapes, lane_problem, mlp_shapes
from records import ENCODINGS, MAX_LANES, N_ACTIONS, SEED_LIMIT, Encoding, GridConfig

MAX_INPUTS = 100_000
"""Largest observation a Q-network model may declare [values]."""
MAX_WIDTH, MAX_LAYERS = 4096, 8
"""Largest hidden layer [units] and number of hidden layers a model may declare."""


def checked_model(
    path: Path | str, expected_algorithms: tuple[str, ...] | None = None
) -> tuple[dict[str, np.ndarray], ModelMetadata]:
    """(arrays, metadata) of `path`, refused with one line (ModelFileError) unless an agent can be
    built from them."""
    arrays, metadata = load_model(path)
    algorithm = metadata.get("algorithm")
    if expected_algorithms and algorithm not in expected_algorithms:
        raise ModelFileError(
            f"{path}: holds a {str(algorithm)[:40]!r} model; expected {' or '.join(expected_algorithms)}"
        )
    _check_metadata(path, metadata)
    for name, value in arrays.items():
        if not np.all(np.isfinite(value)):
            raise ModelFileError(f"{path}: array {name!r} holds NaN or infinite values")
    if metadata["kind"] == "qtable":
        table = arrays.get("q_table")
        if table is None or table.ndim < 2 or table.shape[-1] != N_ACTIONS or len(arrays) != 1:
            raise ModelFileError(
                f"{path}: expected one q_table array whose last axis has {N_ACTIONS} actions"
            )
        return arrays, ModelMetadata.from_json(metadata)
    checked = ModelMetadata.from_json(metadata)
    assert checked.observation_size is not None, "_check_metadata checks a Q-network's input size"
    if checked.kind == "lane-mlp":
        expected = lane_network_shapes(
            checked.grid, checked.observation_size, list(checked.hidden), N_ACTIONS
        )
    else:
        expected = mlp_shapes([checked.observation_size, *checked.hidden, N_ACTIONS])
    expected = ensemble_shapes(expected, checked.members)
    actual = {name: value.shape for name, value in arrays.items()}
    if actual != expected:
        raise ModelFileError(f"{path}: model arrays do not match its metadata (expected {expected})"[:300])
    return arrays, checked


def _check_metadata(path: Path | str, metadata: dict) -> None:
    """One line for the first metadata field the loop cannot use."""
    kind, encoding = metadata.get("kind"), metadata.get("encoding", "tabular")
    problem = None
    if kind not in ("mlp", "lane-mlp", "qtable"):
        problem = "kind: expected 'mlp', 'lane-mlp' or 'qtable'"
    elif encoding not in ENCODINGS:
        problem = f"encoding: expected one of {', '.join(ENCODINGS)}"
    elif kind != "qtable":
        size, hidden, actions = (metadata.get(k) for k in ("observation_size", "hidden", "actions"))
        if not whole_number(size, 1, MAX_INPUTS):
            problem = f"observation_size: expected an integer in 1..{MAX_INPUTS}"
        elif (
            not isinstance(hidden, list)
            or len(hidden) > MAX_LAYERS
            or not all(whole_number(width, 1, MAX_WIDTH) for width in hidden)
        ):
            problem = f"hidden: expected at most {MAX_LAYERS} layer widths in 1..{MAX_WIDTH}"
        elif actions != N_ACTIONS:
            problem = f"actions: the loop commands LEFT, STAY, RIGHT ({N_ACTIONS}), not {str(actions)[:20]}"
    if problem is None:
        try:
            grid = GridConfig.model_validate(metadata.get("grid"))
        except ValidationError as error:
            first = error.errors()[0]
            problem = f"grid.{'.'.join(map(str, first['loc']))}: {first['msg']}"[:200]
        else:
            problem = _prior_problem(metadata.get("mobil_prior", 0.0), grid, encoding)
            if problem is None and kind == "lane-mlp" and (lanes := lane_problem(grid, encoding)):
                problem = f"grid: {lanes}"
    if problem is None and metadata.get("action_mask", False) not in (True, False):
        problem = "action_mask: expected true or false"
    most = 1 if kind == "qtable" else MAX_MEMBERS
    if problem is None and not whole_number(metadata.get("members", 1), 1, most):
        problem = f"members: expected an integer in 1..{most}"
    if problem is None:
        problem = _description_problem(metadata)
    threshold = metadata.get("uncertainty_threshold")
    if problem is None and threshold is not None and not _non_negative(threshold):
        problem = "uncertainty_threshold: expected a number >= 0"
    measure = metadata.get("uncertainty_measure")
    if problem is None and measure is not None and measure not in GATE_MEASURES:
        problem = f"uncertainty_measure: expected one of {', '.join(GATE_MEASURES)}"
    margin = metadata.get("change_margin")
    if problem is None and margin is not None and not (_non_negative(margin) and margin <= MAX_CHANGE_MARGIN):
        problem = f"change_margin: expected a number in [0, {MAX_CHANGE_MARGIN:g}]"
    if problem:
        raise ModelFileError(f"{path}: model metadata {problem}")


def _description_problem(metadata: dict) -> str | None:
    """What is wrong with the fields that say where the model came from (`trained_steps`, `seed`,
    `lanes_count`, `member_seeds`), absent or null when a file does not say: summed or listed by an
    ensemble, a crafted value must not pass as a count or a seed."""
    for key, low, high in (
        ("trained_steps", 0, None),
        ("seed", 0, SEED_LIMIT - 1),
        ("lanes_count", 1, MAX_LANES),
    ):
        value = metadata.get(key)
        if value is not None and not whole_number(value, low, high):
            bounds = f"{low}..{high}" if high is not None else f"at least {low}"
            return f"{key}: expected an integer, {bounds}, got {str(value)[:20]}"
    seeds = metadata.get("member_seeds")
    members = metadata.get("members", 1)
    if seeds is not None and (
        not isinstance(seeds, list)
        or len(seeds) != members
        or not all(whole_number(seed, 0, SEED_LIMIT - 1) for seed in seeds)
    ):
        return f"member_seeds: expected one seed (an integer, 0..{SEED_LIMIT - 1}) per member ({members})"
    return None


def _non_negative(value: object) -> bool:
    """Whether `value` is a finite number >= 0 (not a bool)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    return math.isfinite(value) and value >= 0


def _prior_problem(bonus: object, grid: GridConfig, encoding: Encoding) -> str | None:
    if not isinstance(bonus, int | float) or isinstance(bonus, bool) or not math.isfinite(bonus):
        return "mobil_prior: expected a number"
    return f"mobil_prior: {problem}" if (problem := prior_problem(grid, encoding, bonus)) else None
