"""What a validation measured, as records a model file, a checkpoint and a training summary carry
in JSON (`planner.validation` runs them; this module imports nothing heavy, so a model file's
metadata is read without torch)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class WorldScore:
    """How one world of a validation went: its `episodes`, collision rate and mean speed [m/s]."""

    episodes: int
    collision_rate: float
    mean_speed: float


@dataclass(frozen=True)
class Validation:
    """One validation run: at `step`, over `episodes` episodes; `worlds` splits them by the world
    (scenario) each episode drew, for a training mix."""

    step: int
    period: str
    episodes: int
    collision_rate: float
    mean_return: float
    mean_speed: float
    improved: bool
    worlds: dict[str, WorldScore] = field(default_factory=dict)

    @classmethod
    def from_json(cls, entry: dict[str, Any]) -> Validation:
        worlds = {name: WorldScore(**score) for name, score in entry.get("worlds", {}).items()}
        return cls(**{**entry, "worlds": worlds})

    def line(self) -> str:
        """One line for the progress display: the whole score, then each world's speed [m/s]."""
        worlds = " · ".join(
            f"{name} {score.mean_speed:.1f}"
            + (f" ({score.collision_rate:.0%} crashed)" if score.collision_rate else "")
            for name, score in sorted(self.worlds.items())
        )
        return (
            f"step {self.step} {self.period} validation, {self.episodes} episodes: "
            f"{self.collision_rate:.1%} collisions, return {self.mean_return:.2f}, {self.mean_speed:.2f} m/s"
            + (f" | {worlds}" if len(self.worlds) > 1 else "")
            + (" (kept)" if self.improved and self.period == "long" else "")
        )


def kept_models(history: list[Validation]) -> list[Validation]:
    """The validations of `history` whose model was kept (long ones that improved), in order."""
    return [v for v in history if v.period == "long" and v.improved]
