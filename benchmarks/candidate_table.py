"""A candidate ddqn model against the shipped one and MOBIL, paired episode by episode (same seed),
cell by cell (driver population x world), from `drivestack compare` folders: the candidate's in
CANDIDATE/POPULATION/WORLD (agent `ddqn` with `--models ddqn=FILE`), the shipped model's and MOBIL's
in REFERENCE/POPULATION/WORLD (agents `ddqn,mobil`). Folders WORLD@anything add more seeds to a cell.
Prints one markdown row a cell: speeds [m/s] with paired 95 % t intervals, lane changes an episode
and their ratio to MOBIL's, masked commands an episode, each agent's collisions (at fault), road departures.

    python benchmarks/candidate_table.py runs/eval/pop runs/eval/base
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from stack.runs.statistics import Interval, mean_interval, paired_difference

Episodes = dict[int, dict[str, str]]
"""One agent's episodes in a cell, by seed: the episodes.csv row."""


def cell_episodes(root: Path, population: str, world: str, agent: str) -> Episodes:
    """Agent `agent`'s episodes of one cell under `root`, from WORLD and every WORLD@... folder."""
    found: Episodes = {}
    for folder in sorted((root / population).glob(f"{world}*")):
        if folder.name != world and not folder.name.startswith(f"{world}@"):
            continue
        table = folder / "episodes.csv"
        if not table.is_file():
            continue
        with table.open() as handle:
            for row in csv.DictReader(handle):
                if row["agent"] == agent:
                    found[int(row["seed"])] = row
    return found


def column(episodes: Episodes, seeds: list[int], name: str) -> list[float]:
    """Field `name` of the episodes of `seeds`, as numbers (a flag as 1 or 0)."""
    values = [episodes[seed][name] for seed in seeds]
    return [float(value == "True") if value in ("True", "False") else float(value) for value in values]


def signed(interval: Interval) -> str:
    value, low, high = interval.as_list()
    return f"{value:+.2f} [{low:+.2f}, {high:+.2f}]"


def row(candidate: Path, reference: Path, population: str, world: str) -> str | None:
    """The markdown row of one cell over the seeds all three agents finished, or None if none."""
    agents = {
        "candidate": cell_episodes(candidate, population, world, "ddqn"),
        "shipped": cell_episodes(reference, population, world, "ddqn"),
        "mobil": cell_episodes(reference, population, world, "mobil"),
    }
    seeds = sorted(set.intersection(*(set(episodes) for episodes in agents.values())))
    if not seeds:
        return None
    speed = {name: column(episodes, seeds, "mean_speed") for name, episodes in agents.items()}
    changes = {
        name: float(np.mean(column(episodes, seeds, "lane_changes"))) for name, episodes in agents.items()
    }

    def total(name: str) -> dict[str, int]:
        return {agent: int(sum(column(episodes, seeds, name))) for agent, episodes in agents.items()}

    crashed, at_fault = total("crashed"), total("at_fault_collision")
    mine = agents["candidate"]
    departures = int(sum(column(mine, seeds, "road_departure")))
    masked = float(np.mean(column(mine, seeds, "masked_commands")))
    ratio = f"{changes['candidate'] / changes['mobil']:.2f}x" if changes["mobil"] > 0 else "-"
    collisions = " / ".join(f"{crashed[agent]} ({at_fault[agent]})" for agent in agents)
    return (
        f"| {population} | `{world}` | {len(seeds)} ({seeds[0]}-{seeds[-1]}) "
        f"| {mean_interval(speed['candidate']).value:.2f} "
        f"| {signed(paired_difference(speed['candidate'], speed['mobil']))} "
        f"| {signed(paired_difference(speed['candidate'], speed['shipped']))} "
        f"| {signed(paired_difference(speed['shipped'], speed['mobil']))} "
        f"| {changes['candidate']:.2f} / {changes['shipped']:.2f} / {changes['mobil']:.2f} ({ratio}) "
        f"| {masked:.2f} | {collisions} | {departures} |"
    )


HEADER = (
    "| drivers | world | episodes (seeds) | candidate m/s | candidate - MOBIL m/s [95 %] "
    "| candidate - shipped m/s [95 %] | shipped - MOBIL m/s [95 %] "
    "| lane changes / ep candidate / shipped / MOBIL (candidate / MOBIL) | masked / ep (candidate) "
    "| collisions (at fault) candidate / shipped / MOBIL | road departures (candidate) |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|"
)


def main(arguments: list[str]) -> None:
    if len(arguments) != 2:
        sys.exit("usage: candidate_table.py CANDIDATE_FOLDER REFERENCE_FOLDER")
    candidate, reference = map(Path, arguments)
    print(HEADER)
    for population in sorted(p.name for p in candidate.iterdir() if p.is_dir()):
        worlds = sorted({f.name.split("@")[0] for f in (candidate / population).iterdir() if f.is_dir()})
        for world in worlds:
            if (line := row(candidate, reference, population, world)) is not None:
                print(line)


if __name__ == "__main__":
    main(sys.argv[1:])
