"""The benchmark's score (nuPlan's closed-loop score, for this stack) and its report: the table,
summary.json, benchmark.csv and leaderboard.png.

An episode scores gate x the weighted mean of four sub-scores in [0, 1]:
- **gate** (multiplicative): 0 for an episode with an at-fault collision or a road departure, else 1;
- **progress** (weight 5): how much of what its world allows the episode took
  (`stack.runs.world_allowance`: the mean speeds an ego could hold in the fastest lane, `allowed`,
  and in its own, `own_lane`, from the seed's world at the start). Where another lane allows at
  least `MIN_HEADROOM` more than the ego's own, progress is the share of that headroom gained,
  (mean speed - own_lane) / (allowed - own_lane), clipped to [0, 1]: keeping the lane scores about 0
  there and taking the fastest lane 1. Where no lane allows more, it is mean speed / allowed, capped
  at 1. Against the set speed alone (30 m/s) every safe agent landed within 0.035 of the others,
  since most of its speed is what any agent gets for free; the old score is kept as
  `set_speed_score` (the same score on a world allowing the set speed in every lane);
- **TTC** (weight 5): the share of the episode's time with no vehicle ahead in an occupied lane
  closer than `stack.loop.safety_metrics.TTC_FLOOR_S` (1.5 s) in time to collision;
- **comfort** (weight 2): the share of three bounds kept over the episode: peak lateral acceleration
  <= 2 m/s^2 and peak lateral jerk <= 2.5 m/s^3 (the project's targets, tighter than ISO 11270's 3
  and 5), and no emergency braking;
- **economy** (weight 1): 1 up to `LANE_CHANGE_BUDGET` lane changes a minute, then budget / rate.
An agent's score in a scenario is the mean over its episodes (Student's t interval); its overall
score is the mean over the scenarios, each counted once, with the interval from the scenarios'
half-widths combined in quadrature (the scenarios' episodes are independent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.plugins import short_labels
from stack.results.episode_result import EpisodeResult
from stack.runs.statistics import Interval, mean_interval, rate_interval
from stack.runs.world_allowance import WorldAllowance

WEIGHTS = {"progress": 5.0, "ttc": 5.0, "comfort": 2.0, "economy": 1.0}
"""The sub-scores' weights (nuPlan's: progress 5, TTC 5, comfort 2; economy added here)."""
MAX_LATERAL_ACCELERATION = 2.0
"""Comfort bound on the peak lateral acceleration [m/s^2]."""
MAX_LATERAL_JERK = 2.5
"""Comfort bound on the peak lateral jerk [m/s^3]."""
LANE_CHANGE_BUDGET = 6.0
"""Lane changes a minute that cost no economy [1/min]."""
MIN_HEADROOM = 1.0
"""The least gain over the ego's own lane [m/s] that makes lane choice count in the progress."""
SUBSCORES = tuple(WEIGHTS)
Allowances = dict[str, dict[int, WorldAllowance]]
"""What each episode's world allows, by scenario and seed."""


@dataclass(frozen=True)
class EpisodeScore:
    """One episode's gate (1 kept, 0 failed), sub-scores and score, all in [0, 1]."""

    gate: float
    progress: float
    ttc: float
    comfort: float
    economy: float

    @property
    def score(self) -> float:
        weighted = sum(WEIGHTS[name] * getattr(self, name) for name in SUBSCORES)
        return self.gate * weighted / sum(WEIGHTS.values())


def progress(mean_speed: float, allowance: WorldAllowance) -> float:
    """The progress sub-score of an episode of `mean_speed` [m/s] in a world allowing `allowance`:
    the share of the headroom over the own lane gained, or, with less than `MIN_HEADROOM`, of the
    allowed speed reached."""
    if mean_speed >= allowance.allowed:
        return 1.0
    headroom = allowance.allowed - allowance.own_lane
    if headroom < MIN_HEADROOM:
        return max(mean_speed, 0.0) / allowance.allowed
    return min(1.0, max(0.0, (mean_speed - allowance.own_lane) / headroom))


def set_speed_allowance(set_speed: float) -> WorldAllowance:
    """A world allowing `set_speed` [m/s] in every lane: progress is then mean speed / set speed,
    the score before worlds were measured (`set_speed_score`)."""
    return WorldAllowance(set_speed, set_speed)


def episode_score(episode: EpisodeResult, allowance: WorldAllowance) -> EpisodeScore:
    """`episode` scored in a world allowing `allowance`."""
    duration = max(episode.duration_s, 1e-6)
    comfort = (
        (episode.peak_lat_accel <= MAX_LATERAL_ACCELERATION)
        + (episode.peak_lat_jerk <= MAX_LATERAL_JERK)
        + (episode.emergency_brakings == 0)
    ) / 3
    per_minute = episode.lane_changes * 60.0 / duration
    return EpisodeScore(
        gate=0.0 if episode.at_fault_collision or episode.road_departure else 1.0,
        progress=progress(episode.mean_speed, allowance),
        ttc=min(1.0, max(0.0, 1.0 - episode.time_below_ttc_floor_s / duration)),
        comfort=comfort,
        economy=1.0 if per_minute <= LANE_CHANGE_BUDGET else LANE_CHANGE_BUDGET / per_minute,
    )


def scored(
    episodes: list[EpisodeResult], allowances: dict[int, WorldAllowance], set_speed: float
) -> dict[str, Interval]:
    """One agent's episodes in one scenario (`allowances` by seed): `score`, each sub-score, the
    `failure` rate (the share of gated episodes) and the `set_speed_score`, each with its 95 %
    interval."""
    scores = [episode_score(episode, allowances[episode.seed]) for episode in episodes]
    found = {"score": mean_interval([s.score for s in scores], floor=0.0)}
    for name in SUBSCORES:
        found[name] = mean_interval([getattr(s, name) for s in scores], floor=0.0)
    found["failure"] = rate_interval(sum(s.gate == 0.0 for s in scores), len(scores))
    flat = set_speed_allowance(set_speed)
    found["set_speed_score"] = mean_interval([episode_score(e, flat).score for e in episodes], floor=0.0)
    return found


def combined(parts: list[Interval], floor: float = 0.0) -> Interval:
    """The mean of the scenarios' values, its half-width the quadrature sum of theirs over their
    count (independent scenarios), cut at `floor` (a score cannot be negative; a difference can)."""
    value = float(np.mean([part.value for part in parts]))
    high = math.sqrt(sum((part.high - part.value) ** 2 for part in parts)) / len(parts)
    low = math.sqrt(sum((part.value - part.low) ** 2 for part in parts)) / len(parts)
    return Interval(value, max(floor, value - low), value + high)


def leaderboard(
    results: dict[str, dict[str, list[EpisodeResult]]], allowances: Allowances, set_speed: float
) -> list[dict[str, Any]]:
    """Per agent, best first: `overall` {metric: [value, low, high]} over the scenarios it finished
    and `scenarios` {scenario: {metric: [value, low, high]}}; `results` is {scenario: {agent:
    episodes}}, `set_speed` [m/s] the cruise's (for `set_speed_score`)."""
    agents = list(dict.fromkeys(agent for runs in results.values() for agent in runs))
    rows = []
    for agent in agents:
        per = {
            scenario: scored(runs[agent], allowances[scenario], set_speed)
            for scenario, runs in results.items()
            if runs.get(agent)
        }
        metrics = ("score", *SUBSCORES, "failure", "set_speed_score")
        overall = {metric: combined([found[metric] for found in per.values()]) for metric in metrics}
        rows.append(
            {
                "agent": agent,
                "episodes": sum(len(results[scenario][agent]) for scenario in per),
                "overall": {metric: interval.as_list() for metric, interval in overall.items()},
                "scenarios": {
                    scenario: {metric: interval.as_list() for metric, interval in found.items()}
                    for scenario, found in per.items()
                },
            }
        )
    return sorted(rows, key=lambda row: -row["overall"]["score"][0])


def csv_rows(
    results: dict[str, dict[str, list[EpisodeResult]]], allowances: Allowances, set_speed: float
) -> list[dict[str, Any]]:
    """benchmark.csv: one row per scenario, agent and episode: its score, sub-scores, what its world
    allows [m/s], the set-speed score and its results."""
    rows = []
    flat = set_speed_allowance(set_speed)
    for scenario, runs in results.items():
        for agent, episodes in runs.items():
            for episode in episodes:
                allowance = allowances[scenario][episode.seed]
                score = episode_score(episode, allowance)
                parts = {name: getattr(score, name) for name in ("gate", *SUBSCORES)}
                world = {"allowed_speed": allowance.allowed, "own_lane_speed": allowance.own_lane}
                old = {"set_speed_score": episode_score(episode, flat).score}
                rows.append(
                    {"scenario": scenario, "agent": agent, "score": score.score, **parts, **world, **old}
                    | episode.row()
                )
    return rows


def _cell(interval: list[float], digits: int = 3) -> str:
    value, low, high = interval
    return f"{value:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def markdown(rows: list[dict[str, Any]]) -> str:
    """The leaderboard table (overall) and the score per scenario."""
    names = short_labels([row["agent"] for row in rows])
    header = "| rank | agent | episodes | score | progress | TTC | comfort | economy | failures % |"
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for rank, (row, name) in enumerate(zip(rows, names, strict=True), start=1):
        o = row["overall"]
        failures = [100 * v for v in o["failure"]]
        lines.append(
            f"| {rank} | {name} | {row['episodes']} | {_cell(o['score'])} | {_cell(o['progress'])} | "
            f"{_cell(o['ttc'])} | {_cell(o['comfort'])} | {_cell(o['economy'])} | {_cell(failures, 1)} |"
        )
    scenarios = list(dict.fromkeys(s for row in rows for s in row["scenarios"]))
    header = "| agent | " + " | ".join(scenarios) + " |"
    lines += ["", header, "|" + "---|" * (header.count("|") - 1)]
    for row, name in zip(rows, names, strict=True):
        cells = [_cell(row["scenarios"][s]["score"], 2) if s in row["scenarios"] else "-" for s in scenarios]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_leaderboard(rows: list[dict[str, Any]], title: str, path: Path) -> None:
    """leaderboard.png: the overall score with its interval per agent (best on top), and each
    scenario's score per agent."""
    import matplotlib.pyplot as plt

    from stack.runtime.files import save_figure

    names = short_labels([row["agent"] for row in rows])
    scenarios = list(dict.fromkeys(s for row in rows for s in row["scenarios"]))
    figure, (left, right) = plt.subplots(
        1, 2, figsize=(14, max(3.6, 1.6 + 0.6 * len(rows))), width_ratios=(1, 1.6)
    )
    values = [row["overall"]["score"] for row in rows]
    positions = np.arange(len(rows))[::-1]
    errors = [[v - lo for v, lo, _ in values], [hi - v for v, _, hi in values]]
    left.barh(positions, [v for v, _, _ in values], xerr=errors, capsize=4, color="tab:blue", alpha=0.8)
    left.set_yticks(positions, names)
    left.set_xlim(0, 1)
    left.set_xlabel("benchmark score (0-1; bars: 95 % interval)")
    left.set_title("overall: mean over scenarios", fontsize="medium")
    left.grid(axis="x", alpha=0.3)
    spread = 0.6 / max(len(scenarios) - 1, 1)
    for offset, scenario in enumerate(scenarios):
        shown = [
            (position + 0.3 - spread * offset, row["scenarios"][scenario]["score"][0])
            for position, row in zip(positions, rows, strict=True)
            if scenario in row["scenarios"]
        ]
        right.scatter(
            [value for _, value in shown],
            [position for position, _ in shown],
            label=scenario,
            s=18,
            marker="os^vD<>ph*"[offset % 10],
        )
    right.set_yticks(positions, names)
    right.set_xlim(0, 1)
    right.set_xlabel("score in each scenario (0-1)")
    right.set_title("by scenario", fontsize="medium")
    right.grid(axis="x", alpha=0.3)
    right.legend(fontsize="small", loc="center left", bbox_to_anchor=(1.0, 0.5))
    figure.suptitle(title)
    figure.tight_layout()
    figure.subplots_adjust(right=0.88)
    save_figure(figure, path, dpi=100)
    plt.close(figure)
