"""The uncertainty gate (Hoel et al., arXiv 2004.10439): an ensemble's members rate the command the
ensemble chose; where they disagree by more than a threshold calibrated in distribution, the
decision goes to a fallback agent.

The disagreement is the standard deviation over the members of their Q-values for the chosen
command [Q-value units]. Hoel et al. divide it by the mean (the coefficient of variation); here the
threshold is calibrated for each model file (`drivestack gate-calibrate`), so the ratio's freedom
from the reward's scale buys nothing, and its denominator, the expected return, falls to about 0
where the speed reward does (a jam, a standstill behind a stopped car): the ratio then grows with
no disagreement at all (BENCHMARKS.md measures both)."""

from __future__ import annotations

import numpy as np

from planner.agents import Action, Agent, Gated, Policy
from planner.learned import LearnedAgent


def disagreement(member_q: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """(batch,) the standard deviation over the members of their Q-values for each row's `chosen`
    command; `member_q` is (members, batch, actions). One member: 0."""
    rows = np.arange(member_q.shape[1])
    return np.asarray(member_q[:, rows, chosen].std(axis=0), dtype=float)


def coefficient_of_variation(member_q: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """(batch,) Hoel et al.'s measure: `disagreement` over |the members' mean Q-value| of the
    chosen command (inf where that mean is 0)."""
    rows = np.arange(member_q.shape[1])
    chosen_q = member_q[:, rows, chosen]
    mean = np.abs(chosen_q.mean(axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mean > 0, chosen_q.std(axis=0) / mean, np.inf)


def handed_over(spread: np.ndarray, threshold: float) -> np.ndarray:
    """Per decision, whether the fallback decides: its disagreement above `threshold`."""
    return np.asarray(spread, dtype=float) > threshold


class GatedAgent(Policy):
    """An ensemble `learned` agent whose decisions above `threshold` disagreement [Q-value] go to
    `fallback` (named `fallback_name`; `planner.fallback: none` builds no gate). It shows the loop
    what `learned` must be shown; the loop asks `gate` and, for a handed-over decision,
    the fallback on the fallback's own view (`predict` alone is the ensemble's greedy choice)."""

    def __init__(self, learned: LearnedAgent, fallback: Agent, threshold: float, fallback_name: str) -> None:
        self.learned = learned
        self.fallback = fallback
        self.threshold = threshold
        self.fallback_name = fallback_name
        self.encoding = learned.encoding
        self.grid_config = learned.grid_config
        self.sees_permitted = learned.sees_permitted
        self.observation_size = learned.observation_size
        self.metadata = learned.metadata
        self.source = learned.source
        self.score_name = learned.score_name

    def scores(self, observation: np.ndarray) -> np.ndarray:
        return self.learned.scores(observation)

    def choose(self, observation: np.ndarray) -> Action:
        return self.learned.choose(observation)

    def gate(self, observation: np.ndarray) -> Gated:
        """The ensemble's decision on `observation` (one or a batch of rows) and where it hands over."""
        actions, member_q = self.learned.choose_with_members(observation)
        chosen = np.asarray(actions).reshape(-1)
        spread = disagreement(member_q, chosen)
        return Gated(
            chosen, spread, coefficient_of_variation(member_q, chosen), handed_over(spread, self.threshold)
        )
