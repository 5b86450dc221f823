"""A training run's `summary.json` as a typed record with its JSON round-trip (read by `train`'s
report, a sweep's trials and `--resume`; written by `stack.training.report`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from planner.scores import Validation

NO_CURVE = "not drawn: no validation ran yet"


@dataclass(frozen=True, kw_only=True)
class DemonstrationsUsed:
    """The expert a run learnt from first, its episodes, the transitions they gave, the worlds
    it drove (named scenarios; empty: the training mix), the experts of some of them instead and
    the model file a learned expert decided with (None: its shipped file, or no learned expert)."""

    expert: str
    episodes: int
    transitions: int
    scenarios: tuple[str, ...] = ()
    experts: dict[str, str] = field(default_factory=dict)
    expert_model: str | None = None


@dataclass(frozen=True, kw_only=True)
class TrainSummary:
    """A training run's `summary.json`: `algorithm` and `network`, the steps it was to train
    (`target_steps`) and did (`steps`) in `wall_time_s` [s] (over every resumed part), whether a
    signal `interrupted` it (resumable), the batched `worlds` it stepped (None: per-world envs),
    its `gradient_steps_per_decision` (DDQN / DQN), the demonstrations it learnt from, its best
    (kept) validation, the number of validations, the kept model's path and the training curve's
    file (or why there is none)."""

    algorithm: str
    network: str
    target_steps: int
    steps: int
    wall_time_s: float
    interrupted: bool
    worlds: int | None = None
    gradient_steps_per_decision: float | None = None
    demonstrations: DemonstrationsUsed | None = None
    best_validation: Validation | None
    validations: int
    best_model: str | None
    training_curve: str

    def to_json(self) -> dict[str, Any]:
        """The keys of `summary.json` in their order; `worlds`, `gradient_steps_per_decision` and
        `demonstrations` only when there are some."""
        data: dict[str, Any] = {
            "algorithm": self.algorithm,
            "network": self.network,
            "target_steps": self.target_steps,
            "steps": self.steps,
            "wall_time_s": self.wall_time_s,
            "interrupted": self.interrupted,
        }
        if self.worlds is not None:
            data["worlds"] = self.worlds
        if self.gradient_steps_per_decision is not None:
            data["gradient_steps_per_decision"] = self.gradient_steps_per_decision
        if self.demonstrations is not None:
            data["demonstrations"] = asdict(self.demonstrations)
        return data | {
            "best_validation": asdict(self.best_validation) if self.best_validation else None,
            "validations": self.validations,
            "best_model": self.best_model,
            "training_curve": self.training_curve,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrainSummary:
        """The summary `to_json` wrote (KeyError / TypeError for another object)."""
        demonstrations, best = data.get("demonstrations"), data["best_validation"]
        return cls(
            algorithm=data["algorithm"],
            network=data["network"],
            target_steps=data["target_steps"],
            steps=data["steps"],
            wall_time_s=data["wall_time_s"],
            interrupted=data["interrupted"],
            worlds=data.get("worlds"),
            gradient_steps_per_decision=data.get("gradient_steps_per_decision"),
            demonstrations=_demonstrations(demonstrations) if demonstrations else None,
            best_validation=Validation.from_json(best) if best else None,
            validations=data["validations"],
            best_model=data["best_model"],
            training_curve=data["training_curve"],
        )


def _demonstrations(data: dict[str, Any]) -> DemonstrationsUsed:
    """`DemonstrationsUsed` from its JSON (a summary written before worlds were recorded has none)."""
    return DemonstrationsUsed(**{**data, "scenarios": tuple(data.get("scenarios", ()))})
