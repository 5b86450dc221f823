"""`drivestack gate-calibrate`: the uncertainty gate's threshold (`planner.uncertainty`), a high
percentile of an ensemble's disagreement (by one of `planner.uncertainty.MEASURES`) on the worlds it
trained on, written into its model file with the measure's name.

Each world of the training config's mix (`train.scenarios`) runs `episodes` episodes, one world at a
time, the ensemble deciding every command (no fallback); every decision's disagreement is kept. The
threshold is their `percentile`-th percentile, so that about (100 - percentile) % of the decisions
in distribution go to the fallback."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planner.agents import Agent, Gated
from planner.learned import LearnedAgent, load_agent
from planner.model_file import with_metadata
from planner.uncertainty import DEFAULT_MEASURE, GatedAgent
from records import child_seed
from stack.loop.closed_loop import ClosedLoop
from stack.runs.alone import run_agent_episode
from stack.runs.kept import kept_adapter
from stack.settings.run import RunConfig, training_worlds

DEFAULT_PERCENTILE = 98.5
"""The in-distribution percentile the threshold sits at: 1.5 % of decisions handed over."""


class LoggedGate(GatedAgent):
    """A gate that keeps every decision's disagreement (by `measure`), coefficient of variation, the
    ensemble's command and whether it handed over (by default it never does: an infinite threshold)."""

    def __init__(
        self,
        learned: LearnedAgent,
        fallback: Agent,
        threshold: float = float("inf"),
        name: str = "none",
        measure: str = DEFAULT_MEASURE,
    ) -> None:
        super().__init__(learned, fallback, threshold, name, measure)
        self.disagreements: list[float] = []
        self.variations: list[float] = []
        self.handed: list[bool] = []
        self.actions: list[int] = []

    def gate(self, observation: np.ndarray) -> Gated:
        gated = super().gate(observation)
        self.actions.extend(gated.actions.tolist())
        self.disagreements.extend(gated.disagreement.tolist())
        self.variations.extend(gated.variation.tolist())
        self.handed.extend(gated.handed.tolist())
        return gated


@dataclass
class Calibration:
    """The threshold (in `measure`'s units) at `percentile`, the disagreements it came from by
    world, the coefficients of variation beside them, and the seeds each world ran."""

    percentile: float
    threshold: float
    measure: str = DEFAULT_MEASURE
    disagreements: dict[str, list[float]] = field(default_factory=dict)
    variations: dict[str, list[float]] = field(default_factory=dict)
    seeds: tuple[int, int] = (0, 0)

    def description(self) -> str:
        """One line: how the threshold was found (the model file's `uncertainty_calibration`)."""
        decisions = sum(map(len, self.disagreements.values()))
        worlds = ", ".join(self.disagreements)
        return (
            f"{self.percentile:g}th percentile of {self.measure} over {decisions} "
            f"in-distribution decisions ({worlds}; seeds {self.seeds[0]}-{self.seeds[1]} each)"
        )

    def shares(self) -> dict[str, float]:
        """Per world, the share of its decisions above the threshold (handed over)."""
        return {
            name: float(np.mean(np.array(values) > self.threshold))
            for name, values in self.disagreements.items()
        }


def calibrate(
    config: RunConfig,
    model: Path,
    episodes: int,
    seed: int,
    percentile: float,
    measure: str = DEFAULT_MEASURE,
) -> Calibration:
    """The threshold of `model` by `measure` at `percentile` over `episodes` episodes (seeds
    `seed`...) of each world of `config`'s training mix."""
    learned = load_agent(
        model, expected_algorithms=("ddqn", "dqn"), change_margin=config.planner.change_margin
    )
    if not isinstance(learned, LearnedAgent) or learned.metadata.members < 2:
        raise ValueError(f"{model}: the gate needs an ensemble (a model file of 2 or more members)")
    found = Calibration(percentile, 0.0, measure, seeds=(seed, child_seed(seed, episodes - 1)))
    for name, world in training_worlds(config).items():
        gate = LoggedGate(learned, learned, measure=measure)
        for episode in range(episodes):
            loop = ClosedLoop(world, kept_adapter(world), grid=learned.grid_config)
            run_agent_episode(loop, gate, episode, child_seed(seed, episode))
        found.disagreements[name], found.variations[name] = gate.disagreements, gate.variations
    everything = np.concatenate([np.array(values) for values in found.disagreements.values()])
    found.threshold = float(np.percentile(everything, percentile))
    return found


def write_threshold(model: Path, out: Path, calibration: Calibration) -> Path:
    """`model` written to `out` with the calibrated threshold and its measure in its metadata (its
    weights and other metadata as they were)."""
    fields = {
        "uncertainty_threshold": round(calibration.threshold, 6),
        "uncertainty_measure": calibration.measure,
        "uncertainty_calibration": calibration.description(),
    }
    return with_metadata(model, out, fields)


def calibration_table(calibration: Calibration) -> str:
    """Per world: decisions, the disagreement's median and 98.5th percentile (by the calibrated
    measure, then Hoel et al.'s coefficient of variation), the share handed over."""
    lines = [f"world | decisions | {calibration.measure} median | p98.5 | CV median | CV p98.5 | handed over"]
    shares = calibration.shares()
    for name, values in calibration.disagreements.items():
        spread, variation = np.array(values), np.array(calibration.variations[name])
        lines.append(
            f"{name} | {spread.size} | {np.median(spread):.3f} | {np.percentile(spread, 98.5):.3f} | "
            f"{np.median(variation):.4f} | {np.percentile(variation, 98.5):.4f} | {shares[name]:.1%}"
        )
    return "\n".join(lines)


def calibration_json(calibration: Calibration) -> str:
    return json.dumps(
        {
            "percentile": calibration.percentile,
            "threshold": calibration.threshold,
            "measure": calibration.measure,
            "description": calibration.description(),
            "shares": calibration.shares(),
        },
        indent=2,
    )
