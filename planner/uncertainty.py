"""The uncertainty gate (Hoel et al., arXiv 2004.10439): an ensemble's members rate the command the
ensemble chose; where they disagree by more than a threshold calibrated in distribution, the
decision goes to a fallback agent.

Two measures of the disagreement (`MEASURES`; a model file names the one its threshold was
calibrated for, `uncertainty_measure`):

- `advantage_ratio` (the default): the members' standard deviation of the chosen command's
  advantage over the best other permitted command, over that advantage's mean magnitude
  (`advantage_ratio`): how far the members' spread exceeds the margin the choice was made by.
  It asks whether the members agree on the *choice*, not on the value of a situation they share.
- `std_q`: the members' standard deviation of Q(chosen) [Q-value] (`disagreement`): it grows with
  the return's own spread, so it flags situations whose value is uncertain whatever is chosen.

Hoel et al. divide the standard deviation of Q(chosen) by its mean (`coefficient_of_variation`); its
denominator, the expected return, falls to about 0 where the speed reward does (a jam, a
standstill behind a stopped car), and the ratio then grows with no disagreement at all. Measured
against the probes: BENCHMARKS.md, "The uncertainty gate"."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from planner.agents import Action, Agent, Gated, Policy
from planner.learned import LearnedAgent
from planner.model_metadata import GATE_MEASURES, ModelMetadata
from records import N_ACTIONS


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


def advantages(member_q: np.ndarray, chosen: np.ndarray, permitted: np.ndarray | None) -> np.ndarray:
    """(members, batch) each member's advantage of each row's `chosen` command over the best other
    permitted one [Q-value]: Q(chosen) - max Q(other permitted); NaN where no other is permitted
    (`permitted` (batch, actions), 1 permitted; None: all are)."""
    _, batch, actions = member_q.shape
    rows = np.arange(batch)
    others = np.ones((batch, actions), dtype=bool) if permitted is None else np.asarray(permitted) > 0.5
    others = others.copy()
    others[rows, chosen] = False
    best_other = np.where(others[None], member_q, -np.inf).max(axis=2)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(best_other), member_q[:, rows, chosen] - best_other, np.nan)


def advantage_disagreement(
    member_q: np.ndarray, chosen: np.ndarray, permitted: np.ndarray | None = None
) -> np.ndarray:
    """(batch,) the standard deviation over the members of their advantage of the chosen command
    over the best other permitted one [Q-value] (`advantages`); 0 where no other is permitted: the
    members disagree about the choice, not about the value of the situation they share."""
    return np.nan_to_num(advantages(member_q, chosen, permitted).std(axis=0), nan=0.0)


def dissenting_share(
    member_q: np.ndarray, chosen: np.ndarray, permitted: np.ndarray | None = None
) -> np.ndarray:
    """(batch,) the share of members that would choose another permitted command than `chosen`
    (each member's greedy command among the permitted; 0 where no other is permitted)."""
    return np.nan_to_num((advantages(member_q, chosen, permitted) < 0).mean(axis=0), nan=0.0)


def advantage_ratio(
    member_q: np.ndarray, chosen: np.ndarray, permitted: np.ndarray | None = None
) -> np.ndarray:
    """(batch,) the members' standard deviation of the chosen command's advantage over the best
    other permitted one, over the magnitude of its mean (`advantages`; dimensionless: above 1 the
    members' spread exceeds the margin the choice was made by); 0 where no other is permitted."""
    found = advantages(member_q, chosen, permitted)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = found.std(axis=0) / np.maximum(np.abs(found.mean(axis=0)), 1e-6)
    return np.nan_to_num(ratio, nan=0.0)


MEASURES: dict[str, Callable[[np.ndarray, np.ndarray, np.ndarray | None], np.ndarray]] = {
    "advantage_ratio": advantage_ratio,
    "std_q": lambda member_q, chosen, permitted: disagreement(member_q, chosen),
}
"""Each gate measure by the name a model file's `uncertainty_measure` gives: (members, batch,
actions) Q-values, (batch,) chosen commands, (batch, actions) permitted or None -> (batch,)."""
assert tuple(MEASURES) == GATE_MEASURES
DEFAULT_MEASURE = "advantage_ratio"
CALIBRATED_BEFORE_NAMES = "std_q"
"""The measure of a model file calibrated before measures were named (a threshold, no measure)."""


def gate_measure(metadata: ModelMetadata) -> str:
    """The measure `metadata`'s threshold belongs to: the one it names, else `std_q` when it holds
    a threshold (calibrated before measures were named), else `DEFAULT_MEASURE`."""
    if metadata.uncertainty_measure is not None:
        return metadata.uncertainty_measure
    return CALIBRATED_BEFORE_NAMES if metadata.uncertainty_threshold is not None else DEFAULT_MEASURE


def compared_as_chosen(member_q: np.ndarray, rated: np.ndarray) -> np.ndarray:
    """(members, batch, actions) each member's Q-values with the bonus the ensemble's choice added
    to their mean (`rated` (batch, actions): the MOBIL prior's, the same for every member), so that
    an advantage is the one the choice weighed."""
    return member_q + (np.asarray(rated) - member_q.mean(axis=0))[None]


def handed_over(spread: np.ndarray, threshold: float) -> np.ndarray:
    """Per decision, whether the fallback decides: its disagreement above `threshold`."""
    return np.asarray(spread, dtype=float) > threshold


class GatedAgent(Policy):
    """An ensemble `learned` agent whose decisions above `threshold` disagreement (by `measure`, a
    name of `MEASURES`) go to `fallback` (named `fallback_name`; `planner.fallback: none` builds no
    gate). It shows the loop what `learned` must be shown; the loop asks `gate` and, for a
    handed-over decision, the fallback on the fallback's own view (`predict` alone is the
    ensemble's greedy choice)."""

    def __init__(
        self,
        learned: LearnedAgent,
        fallback: Agent,
        threshold: float,
        fallback_name: str,
        measure: str = DEFAULT_MEASURE,
    ) -> None:
        self.learned = learned
        self.fallback = fallback
        self.threshold = threshold
        self.fallback_name = fallback_name
        self.measure = measure
        self.measured = MEASURES[measure]
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
        """The ensemble's decision on `observation` (one or a batch of rows) and where it hands over
        (per world and batched alike: the batch calls this on each world's row)."""
        actions, member_q = self.learned.choose_with_members(observation)
        chosen = np.asarray(actions).reshape(-1)
        permitted = None
        if self.learned.sees_permitted:
            permitted = np.asarray(observation).reshape(len(chosen), -1)[:, -N_ACTIONS:] >= 0.5
        spread = self.measured(compared_as_chosen(member_q, self.learned.last_rated[1]), chosen, permitted)
        return Gated(
            chosen, spread, coefficient_of_variation(member_q, chosen), handed_over(spread, self.threshold)
        )
