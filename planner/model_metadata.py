"""What a model file says about its model (`planner.model_file`'s JSON metadata member) as one
typed record: written by the trainer, read by every loader, its JSON keys those of every file
written so far (the shipped models and old run folders load as they are)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Literal

from planner.scores import Validation
from records import N_ACTIONS, Encoding, GridConfig

ModelKind = Literal["mlp", "lane-mlp", "qtable"]

MAX_CHANGE_MARGIN = 10.0
"""Largest change margin [Q-value] a run config or a model file may set: the shipped ensemble's
Q-values span about 0-80, and its changes' advantages over STAY rarely exceed a few units."""
GATE_MEASURES = ("advantage_ratio", "std_q")
"""The names a model file's `uncertainty_measure` may give (`planner.uncertainty.MEASURES`)."""


@dataclass(frozen=True, kw_only=True)
class ModelMetadata:
    """`kind` (a Q-network `mlp`, a lane network `lane-mlp` or a Q-`qtable`), the `algorithm`
    that trained it, the `encoding` and `grid` of the observations it takes (`observation_size`
    values), its `actions` and `hidden` layer widths (a lane network's: its head's), the `network`
    size name, the `lanes_count` of the road it trained on, the `trained_steps`, the training
    `seed` and the `validation` that kept it (an ensemble: its `member_seeds` instead). Only
    `kind`, `grid`, for a Q-network the sizes and its `mobil_prior` (the bonus its greedy
    decision gives MOBIL's proposed change, `planner.mobil.MobilPrior`; 0: none, and not
    written) and its `action_mask` (its observations end with the safety layer's permitted
    commands, and it decides among them; False: not written) and its `members` (an ensemble of
    that many Q-networks of these sizes deciding on their mean, `planner.learned.MeanQNetwork`;
    1: not written) are needed to use it (`planner.model_check` checks them), and an ensemble's
    `uncertainty_threshold` (the members' disagreement above which a fallback decides,
    `planner.uncertainty`, by the measure `uncertainty_measure` names; with how it was calibrated,
    `uncertainty_calibration`: None when never calibrated) to gate it, and its `change_margin`
    (the Q-value by which a lane change must beat STAY, `planner.learned.LearnedAgent`; with how it
    was calibrated, `change_margin_calibration`: None when never calibrated, and the agent then
    decides on its plain argmax) to decide; the rest
    describes where it came from and is None (`member_seeds`: empty) in a file that does not say."""

    kind: ModelKind
    algorithm: str | None = None
    encoding: Encoding = "tabular"
    observation_size: int | None = None
    actions: int = N_ACTIONS
    hidden: tuple[int, ...] = ()
    network: str | None = None
    grid: GridConfig
    lanes_count: int | None = None
    trained_steps: int | None = None
    seed: int | None = None
    validation: Validation | None = None
    mobil_prior: float = 0.0
    action_mask: bool = False
    members: int = 1
    member_seeds: tuple[int, ...] = ()
    uncertainty_threshold: float | None = None
    uncertainty_calibration: str | None = None
    uncertainty_measure: str | None = None
    change_margin: float | None = None
    change_margin_calibration: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The metadata member's keys in the order drivestack has always written them; a field
        that is None is left out."""
        data = {
            "kind": self.kind,
            "algorithm": self.algorithm,
            "encoding": self.encoding,
            "observation_size": self.observation_size,
            "actions": self.actions,
            "hidden": list(self.hidden),
            "network": self.network,
            "grid": self.grid.model_dump(mode="json"),
            "lanes_count": self.lanes_count,
            "trained_steps": self.trained_steps,
            "seed": self.seed,
            "validation": asdict(self.validation) if self.validation is not None else None,
            "mobil_prior": self.mobil_prior or None,
            "action_mask": self.action_mask or None,
            "members": self.members if self.members > 1 else None,
            "member_seeds": list(self.member_seeds) or None,
            "uncertainty_threshold": self.uncertainty_threshold,
            "uncertainty_calibration": self.uncertainty_calibration,
            "uncertainty_measure": self.uncertainty_measure,
            "change_margin": self.change_margin,
            "change_margin_calibration": self.change_margin_calibration,
        }
        return {key: value for key, value in data.items() if value is not None}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> ModelMetadata:
        """The record of metadata `planner.model_check` has checked (kind, encoding, grid and a
        Q-network's sizes); a descriptive field of another type than its own reads as None."""
        hidden = data.get("hidden")
        return cls(
            kind=data["kind"],
            algorithm=_typed(data, "algorithm", str),
            encoding=data.get("encoding", "tabular"),
            observation_size=_typed(data, "observation_size", int),
            actions=_typed(data, "actions", int) or N_ACTIONS,
            hidden=tuple(hidden) if isinstance(hidden, list) and _all_int(hidden) else (),
            network=_typed(data, "network", str),
            grid=GridConfig.model_validate(data["grid"]),
            lanes_count=_typed(data, "lanes_count", int),
            trained_steps=_typed(data, "trained_steps", int),
            seed=_typed(data, "seed", int),
            validation=_validation(data.get("validation")),
            mobil_prior=float(data.get("mobil_prior", 0.0)),
            action_mask=data.get("action_mask", False) is True,
            members=_typed(data, "members", int) or 1,
            member_seeds=_member_seeds(data),
            uncertainty_threshold=_number(data.get("uncertainty_threshold")),
            uncertainty_calibration=_typed(data, "uncertainty_calibration", str),
            uncertainty_measure=_typed(data, "uncertainty_measure", str),
            change_margin=_number(data.get("change_margin")),
            change_margin_calibration=_typed(data, "change_margin_calibration", str),
        )


def _member_seeds(data: dict[str, Any]) -> tuple[int, ...]:
    """An ensemble's training seeds, one a member (none when the file does not say them all)."""
    seeds = data.get("member_seeds")
    if isinstance(seeds, list) and _all_int(seeds) and len(seeds) == data.get("members"):
        return tuple(seeds)
    return ()


def _number(value: object) -> float | None:
    """`value` as a float when it is a number (not a bool), else None."""
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def _typed(data: dict[str, Any], key: str, kind: type) -> Any:
    value = data.get(key)
    return value if isinstance(value, kind) and not isinstance(value, bool) else None


def whole_number(value: object, low: int | None = None, high: int | None = None) -> bool:
    """Whether `value` is an int, not a bool (JSON's true is not 1 layer), within [low, high]."""
    if not isinstance(value, int) or isinstance(value, bool):
        return False
    return (low is None or value >= low) and (high is None or value <= high)


def _all_int(values: list[Any]) -> bool:
    return all(map(whole_number, values))


def _validation(data: object) -> Validation | None:
    if not isinstance(data, dict):
        return None
    try:
        return Validation.from_json(data)
    except (TypeError, ValueError, AttributeError):
        return None
