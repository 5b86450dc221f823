"""`drivestack benchmark`: every agent on every named scenario on fixed report seeds, one score per
agent (`stack.apps.benchmark_report`). Each scenario runs as a `compare` of the agents (the same
machinery: processes or Ray, one journal per agent, per-scenario comparison.json and figure) in
its own subfolder; the benchmark folder holds the resolved config, summary.json, benchmark.csv and
leaderboard.png. `--resume` finishes an interrupted benchmark: each scenario's journals give back
its finished episodes, and only the rest run. With several driver populations (`--traffic A,B`,
a traffic axis) each population's benchmark runs in its own subfolder, and the benchmark folder's
summary.json and printed table hold each agent's score per population (`run_traffic_axis`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any

from stack.apps.benchmark_report import (
    LANE_CHANGE_BUDGET,
    MIN_HEADROOM,
    WEIGHTS,
    Allowances,
    csv_rows,
    leaderboard,
    markdown,
    plot_leaderboard,
)
from stack.apps.compare import compare, comparison, population_line, write_comparison
from stack.apps.resume import journal_of, journaled, resolved_config, started
from stack.loop.safety_metrics import TTC_FLOOR_S
from stack.results.episode_result import EpisodeResult
from stack.runs.batch_episodes import batches
from stack.runs.world_allowance import WorldAllowance, world_allowances
from stack.runtime.executors import completed, shared_workers
from stack.runtime.files import write_csv, write_json, write_text
from stack.runtime.interrupts import deferred
from stack.settings.run import RunConfig, drivers_of, in_scenario
from stack.worlds import scenarios

REPORT_SEED = 970_000
"""The first seed of the benchmark's episodes (report seeds: never trained, selected or tuned on)."""
FULL_EPISODES = 500
"""Episodes per scenario of the full benchmark."""
FULL_RANDOM_EPISODES = 300
"""Episodes of the `random` scenario in the full benchmark."""
QUICK_EPISODES = 4
"""Episodes per scenario with --quick (5 agents on 10 scenarios in under 3 minutes on 2 cores)."""
RANDOM = "random"
ALLOWANCE_BATCH_SEEDS = 100
"""Seeds a work item resets for their worlds' allowances (about 1 s of work)."""


@dataclass(frozen=True)
class BenchmarkPlan:
    """The scenarios run, the episodes of each (`random`'s own count), the first seed and, for
    smoke tests only, an episode length [s] replacing the scenarios' own."""

    scenarios: tuple[str, ...]
    episodes: int
    random_episodes: int
    seed: int = REPORT_SEED
    duration_s: float | None = None

    @classmethod
    def chosen(
        cls,
        quick: bool,
        episodes: int | None = None,
        seed: int = REPORT_SEED,
        duration_s: float | None = None,
    ) -> BenchmarkPlan:
        """The full plan, or --quick's, or `episodes` per scenario (random included) when given."""
        if episodes is not None:
            return cls(scenarios.names(), episodes, episodes, seed, duration_s)
        if quick:
            return cls(scenarios.names(), QUICK_EPISODES, QUICK_EPISODES, seed, duration_s)
        return cls(scenarios.names(), FULL_EPISODES, FULL_RANDOM_EPISODES, seed, duration_s)

    def episodes_of(self, scenario: str) -> int:
        return self.random_episodes if scenario == RANDOM else self.episodes

    def configs(self, configs: list[RunConfig], scenario: str) -> list[RunConfig]:
        """Each agent's config moved to `scenario`, with its episodes and the plan's seed."""
        update = {"episodes": self.episodes_of(scenario), "seed": self.seed}
        moved = [in_scenario(config, scenario).model_copy(update=update) for config in configs]
        if self.duration_s is None:
            return moved
        road = {"duration": self.duration_s}
        return [c.model_copy(update={"highway": c.highway.model_copy(update=road)}) for c in moved]


def finished_before(configs: list[RunConfig], folder: Path) -> dict[str, list[EpisodeResult]]:
    """Per agent, the episodes an interrupted benchmark journaled in the scenario `folder`."""
    return {
        config.planner.agent: journaled(config, journal) if journal.path.is_file() else []
        for config in configs
        for journal in (journal_of(config, folder),)
    }


def allowances_of(
    config: RunConfig, runs: dict[str, list[EpisodeResult]], jobs: int = 1, ray: str | None = None
) -> dict[int, WorldAllowance]:
    """What each seed the agents ran in `config`'s world allows (one reset of the world a seed),
    over the benchmark's processes or Ray tasks (here with `jobs` 1: a stopped benchmark's)."""
    seeds = sorted({episode.seed for episodes in runs.values() for episode in episodes})
    if jobs <= 1 and ray is None:
        return dict(zip(seeds, world_allowances(config, seeds), strict=True))
    parts = batches(seeds, jobs if ray is None else 1, ALLOWANCE_BATCH_SEEDS)
    found: dict[int, WorldAllowance] = {}
    for index, allowances in completed(partial(world_allowances, config), parts, jobs, ray):
        found.update(zip(parts[index], allowances, strict=True))
    return found


def run_benchmark(
    configs: list[RunConfig],
    plan: BenchmarkPlan,
    out: Path,
    jobs: int = 1,
    progress: bool = True,
    ray: str | None = None,
    resuming: bool = False,
) -> tuple[bool, list[dict[str, Any]]]:
    """Run `plan` for the agents of `configs` (one per agent) into `out`, write the report, print
    the leaderboard; whether Ctrl-C cut it short (the scenarios run so far are reported, the
    journals kept for --resume), and the leaderboard's rows."""
    write_text(out / "config.yaml", resolved_config(configs))
    results: dict[str, dict[str, list[EpisodeResult]]] = {}
    allowances: Allowances = {}
    journals = []
    interrupted = False
    with shared_workers():
        for scenario in plan.scenarios:
            scenario_configs = plan.configs(configs, scenario)
            folder = out / scenario
            folder.mkdir(exist_ok=True)
            done = finished_before(scenario_configs, folder) if resuming else None
            kept = started(scenario_configs, folder, done)
            journals += kept
            try:
                runs = compare(scenario_configs, kept, jobs=jobs, progress=progress, ray=ray, done=done)
            except KeyboardInterrupt:
                interrupted = True
                break
            results[scenario] = {run.summary["agent"]: run.episodes for run in runs}
            stopped = len(runs) < len(configs) or bool(runs[-1].summary["interrupted"])
            with deferred(interrupt_after=False):
                allowances[scenario] = allowances_of(
                    scenario_configs[0], results[scenario], *((1, None) if stopped else (jobs, ray))
                )
                write_comparison(comparison(runs), folder)
            if stopped:
                interrupted = True
                break
    if not results:
        raise KeyboardInterrupt
    set_speed = configs[0].controller.set_speed_mps
    rows = leaderboard(results, allowances, set_speed)
    drivers = drivers_of(configs[0].highway)
    with deferred(interrupt_after=False):
        write_json(
            out / "summary.json",
            {
                "plan": asdict(plan),
                "drivers": drivers,
                "interrupted": interrupted,
                "set_speed_mps": set_speed,
                "min_headroom_mps": MIN_HEADROOM,
                "weights": WEIGHTS,
                "ttc_floor_s": TTC_FLOOR_S,
                "lane_change_budget_per_min": LANE_CHANGE_BUDGET,
                "leaderboard": rows,
            },
        )
        write_csv(out / "benchmark.csv", csv_rows(results, allowances, set_speed))
        done_count = sum(len(episodes) for runs in results.values() for episodes in runs.values())
        title = (
            f"drivestack benchmark: {len(results)} scenarios, {done_count} episodes from seed {plan.seed}"
            + (" (interrupted)" if interrupted else "")
        )
        plot_leaderboard(rows, title, out / "leaderboard.png")
        for journal in journals if not interrupted else []:
            journal.discard()
    print(population_line({"drivers": drivers}) + markdown(rows), end="")
    resumable = " (interrupted: the same command with --resume finishes it)"
    print(f"results: {out}" + (resumable if interrupted else ""))
    return interrupted, rows


def run_traffic_axis(
    populations: dict[str, list[RunConfig]],
    plan: BenchmarkPlan,
    out: Path,
    jobs: int = 1,
    progress: bool = True,
    ray: str | None = None,
    resuming: bool = False,
) -> bool:
    """The benchmark under each driver population (`populations`: the agents' configs by
    population name), each in out/POPULATION; then out/summary.json and the printed table of each
    agent's overall score per population (`traffic_table`). True when Ctrl-C cut it short (the
    populations finished so far are reported)."""
    boards: dict[str, list[dict[str, Any]]] = {}
    interrupted = False
    for name, configs in populations.items():
        folder = out / name
        folder.mkdir(exist_ok=True)
        try:
            interrupted, boards[name] = run_benchmark(configs, plan, folder, jobs, progress, ray, resuming)
        except KeyboardInterrupt:
            interrupted = True
        if interrupted:
            break
    if not boards:
        raise KeyboardInterrupt
    table = traffic_table(boards)
    with deferred(interrupt_after=False):
        write_json(
            out / "summary.json",
            {
                "plan": asdict(plan),
                "interrupted": interrupted,
                "populations": list(boards),
                "scores": {
                    next(iter(by.values()))["agent"]: {
                        name: row["overall"]["score"] for name, row in by.items()
                    }
                    for by in table
                },
                "leaderboards": boards,
            },
        )
    print(traffic_markdown(table, list(boards)), end="")
    print(f"results: {out}" + (" (interrupted)" if interrupted else ""))
    return interrupted


def traffic_table(boards: dict[str, list[dict[str, Any]]]) -> list[dict[str, dict[str, Any]]]:
    """Per agent (in the first population's rank order), its leaderboard row in each population."""
    first = next(iter(boards.values()))
    return [
        {name: row for name, rows in boards.items() for row in rows if row["agent"] == leader["agent"]}
        for leader in first
    ]


def traffic_markdown(table: list[dict[str, dict[str, Any]]], populations: list[str]) -> str:
    """The agents x populations table: each agent's overall score [95 % interval] and its rank under
    each population."""
    header = "| agent | " + " | ".join(populations) + " |"
    lines = [header, "|" + "---|" * (len(populations) + 1)]
    ranks = {
        name: {row["agent"]: rank for rank, row in enumerate(sorted(
            (by[name] for by in table if name in by), key=lambda row: -row["overall"]["score"][0]), 1)}
        for name in populations
    }  # fmt: skip
    for by in table:
        agent = next(iter(by.values()))["agent"]
        cells = [
            f"{_score_cell(by[name]['overall']['score'])} (#{ranks[name][agent]})" if name in by else "-"
            for name in populations
        ]
        lines.append(f"| {agent} | " + " | ".join(cells) + " |")
    return (
        "agents x traffic drivers: overall benchmark score [95 % interval] (rank)\n\n"
        + "\n".join(lines)
        + "\n"
    )


def _score_cell(interval: list[float]) -> str:
    value, low, high = interval
    return f"{value:.3f} [{low:.3f}, {high:.3f}]"
