"""A sweep file (`drivestack sweep --config SWEEP.yaml`): which training runs to try.

    config: ddqn.yaml                 # the base training config (relative to this file)
    fixed: {train.steps: 20000}       # overrides every trial shares (dotted keys, as --set)
    space:                            # what varies between trials (dotted keys, as --set)
      seed: [1, 2, 3]                            # a list: grid search, every value
      train.learning_rate: {loguniform: [1.0e-4, 1.0e-3]}   # random: drawn per trial
      train.gamma: {uniform: [0.9, 0.99]}
      train.batch_size: {randint: [32, 129]}     # low inclusive, high exclusive
      train.network: {choice: [shallow, deep]}
    samples: 1                        # trials per grid point (random values drawn afresh)
    metric: mean_return               # of each trial's best long validation (see METRICS)
    concurrent: null                  # trials at once (default: as many as the CPUs hold)

Every key and every candidate value (grid values, range bounds, choices) is checked against the
base config before any trial starts, so a typo is one line, not a failed trial an hour later; a
boolean is not a number, a random range over an integer key is `randint`, and a sweep holds at most
`MAX_TRIALS` trials.
"""

from __future__ import annotations

import math
import re
import types
import typing
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, Field, ValidationError, field_validator

from stack.settings.checks import boolean_mismatch
from stack.settings.run import NULL, ConfigError, RunConfig, load_config, one_line, printable, read_mapping
from stack.settings.train import Strict

SWEEP_FILE = "sweep.yaml"
"""The sweep file a sweep folder keeps (`--resume` reads it)."""
METRICS = {"mean_return": "max", "mean_speed": "max", "collision_rate": "min"}
"""Trial metrics (a kept model's long validation) and whether higher or lower is better."""
RANGES = ("uniform", "loguniform", "randint")
"""Random distributions over [low, high) given as [low, high]."""
DISTRIBUTIONS = (*RANGES, "choice")
DOTTED_KEY = re.compile(r"[A-Za-z_][\w-]*(\.[A-Za-z_][\w-]*)*")
"""A config key as `--set` takes it (`stack.apps.options.SET_KEY`)."""
MAX_VALUES = 1_000
"""Most values one grid list or choice may hold."""
MAX_TRIALS = 10_000
"""Most trials a sweep may ask for (grid points x samples)."""


class SweepFile(Strict):
    config: Path
    fixed: dict[str, Any] = {}
    space: dict[str, list[Any] | dict[str, list[Any]]] = Field(min_length=1, max_length=100)
    samples: int = Field(1, ge=1, le=10_000)
    metric: Literal["mean_return", "mean_speed", "collision_rate"] = "mean_return"
    concurrent: int | None = Field(None, ge=1, le=1024)

    @field_validator("fixed")
    @classmethod
    def _dotted(cls, fixed: dict[str, Any]) -> dict[str, Any]:
        for key in fixed:
            if not DOTTED_KEY.fullmatch(key):
                raise ValueError(f"{key[:80]!r}: expected a dotted config key (as --set takes)")
        return fixed

    @field_validator("space", mode="before")
    @classmethod
    def _shaped(cls, space: object) -> object:
        """Dotted keys, each with a list or a one-key mapping to a list (before pydantic's own
        messages, which would name the union's members instead)."""
        for key, values in space.items() if isinstance(space, dict) else ():
            if not isinstance(key, str) or not DOTTED_KEY.fullmatch(key):
                raise ValueError(f"{str(key)[:80]!r}: expected a dotted config key (as --set takes)")
            distribution = isinstance(values, dict) and all(isinstance(v, list) for v in values.values())
            if not isinstance(values, list) and not distribution:
                raise ValueError(
                    f"{key}: expected a list (grid) or one of {{{'|'.join(DISTRIBUTIONS)}: [...]}}"
                )
        return space

    @field_validator("space")
    @classmethod
    def _non_empty(cls, space: dict[str, list[Any] | dict[str, list[Any]]]) -> dict:
        for key, values in space.items():
            if isinstance(values, list):
                if not values:
                    raise ValueError(f"{key}: expected a non-empty list of values, got []")
            else:
                _check_distribution(key, values)
            if len(candidates(values)) > MAX_VALUES:
                raise ValueError(f"{key}: at most {MAX_VALUES} values, got {len(candidates(values))}")
        return space

    @property
    def trials(self) -> int:
        """How many trials the sweep asks for: every grid point, `samples` times."""
        return self.samples * math.prod(len(v) for v in self.space.values() if isinstance(v, list))

    @property
    def mode(self) -> str:
        """`max` or `min`: which way the metric improves."""
        return METRICS[self.metric]


def _check_distribution(key: str, values: dict[str, list[Any]]) -> None:
    """One of DISTRIBUTIONS with a non-empty range or choice; ValueError (one line) otherwise."""
    if len(values) != 1 or next(iter(values)) not in DISTRIBUTIONS:
        raise ValueError(f"{key}: expected a list (grid) or one of {{{'|'.join(DISTRIBUTIONS)}: [...]}}")
    (kind, bounds), *_ = values.items()
    if kind == "choice":
        if not bounds:
            raise ValueError(f"{key}: choice: expected a non-empty list of values, got []")
        return
    numbers = len(bounds) == 2 and all(isinstance(b, int | float) and not isinstance(b, bool) for b in bounds)
    if not numbers or (kind == "randint" and not all(isinstance(b, int) for b in bounds)):
        number = "integers" if kind == "randint" else "numbers"
        raise ValueError(f"{key}: {kind}: expected [low, high], two {number}, got {bounds}")
    low, high = bounds
    if not low < high:
        raise ValueError(f"{key}: {kind}: empty range [{low}, {high}); expected low < high")
    if kind == "loguniform" and low <= 0:
        raise ValueError(f"{key}: loguniform: expected 0 < low, got {low}")


def candidates(values: list[Any] | dict[str, list[Any]]) -> list[Any]:
    """The values of one space entry worth checking: grid values, choices, or a range's ends."""
    if isinstance(values, list):
        return values
    (kind, bounds), *_ = values.items()
    return [bounds[0], bounds[1] - 1] if kind == "randint" else list(bounds)


def overrides(settings: dict[str, Any]) -> dict[str, Any]:
    """Dotted keys and values of a sweep (`fixed`, a trial's params) as `load_config` takes them: a
    null sets null (`load_config` would skip a plain None)."""
    return {key.replace(".", "__"): NULL if value is None else value for key, value in settings.items()}


def trial_config(base: Path, fixed: dict[str, Any], params: dict[str, Any]) -> RunConfig:
    """The training config of one trial: the base file with `params` and `fixed` applied (a
    `scenario` among them moves the base to that world first, so every fixed key still holds)."""
    return load_config(base, **overrides({**fixed, **params}))


def load_sweep(path: Path) -> tuple[SweepFile, Path, list[RunConfig]]:
    """The sweep file at `path`, its base config's path and the trial configs every key's every
    candidate value gives (the base first), all checked; ConfigError (one line naming the file and
    key) otherwise."""
    data = read_mapping(path)
    if mismatch := boolean_mismatch(SweepFile, data):
        raise ConfigError(printable(f"{path}: {mismatch[0]}: {mismatch[1]}"))
    try:
        sweep = SweepFile.model_validate(data)
    except ValidationError as error:
        raise ConfigError(one_line(error, str(path), {})) from None
    if sweep.trials > MAX_TRIALS:
        raise ConfigError(f"{path}: space: {sweep.trials} trials; a sweep holds at most {MAX_TRIALS}")
    base = sweep.config if sweep.config.is_absolute() else path.parent / sweep.config
    if not base.is_file():
        raise ConfigError(f"{path}: config: no such training config {base}")
    fixed = overrides(sweep.fixed)
    labels = {key: f"{path}: fixed" for key in sweep.fixed}
    configs = [load_config(base, labels, **fixed)]
    for key, values in sweep.space.items():
        labels[key] = f"{path}: space"
        if isinstance(values, dict) and "randint" not in values and "choice" not in values:
            if integer_key(key):
                raise ConfigError(
                    f"{path}: space: {key}: an integer; draw it with randint or list its values"
                )
        for value in candidates(values):
            configs.append(load_config(base, labels, **{**fixed, **overrides({key: value})}))
    if any(config.train.members > 1 for config in configs):
        raise ConfigError(
            f"{path}: train.members: a trial trains one model; add train.members: 1 to fixed, sweep the seed"
        )
    return sweep, base, configs


def integer_key(dotted: str) -> bool:
    """Whether the config key `dotted` takes integers only (a uniform draw would be fractional)."""
    kind: Any = RunConfig
    for part in dotted.split("."):
        if isinstance(kind, type) and issubclass(kind, BaseModel) and part in kind.model_fields:
            kind = kind.model_fields[part].annotation
        elif typing.get_origin(kind) is dict:
            kind = typing.get_args(kind)[1]
        else:
            return False
        union = typing.get_origin(kind) in (typing.Union, types.UnionType)
        kinds = typing.get_args(kind) if union else (kind,)
        kind = next((k for k in kinds if isinstance(k, type) and issubclass(k, BaseModel)), kind)
    kinds = typing.get_args(kind) or (kind,)
    return int in kinds and float not in kinds
