"""`drivestack benchmark`: every agent on every named scenario on fixed report seeds, one score per
agent (`stack.apps.benchmark_report`). Each scenario runs as a `compare` of the agents (the same
machinery: processes or Ray, one journal per agent, per-scenario comparison.json and figure) in
its own subfolder; the benchmark folder holds the resolved config, summary.json, benchmark.csv and
leaderboard.png. `--resume` finishes an interrupted benchmark: each scenario's journals give back
its finished episodes, and only the rest run."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path

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
from stack.apps.compare import compare, comparison, write_comparison
from stack.apps.resume import journal_of, journaled, resolved_config, started
from stack.loop.safety_metrics import TTC_FLOOR_S
from stack.results.episode_result import EpisodeResult
from stack.runs.batch_episodes import batches
from stack.runs.world_allowance import WorldAllowance, world_allowances
from stack.runtime.executors import completed, shared_workers
from stack.runtime.files import write_csv, write_json, write_text
from stack.runtime.interrupts import deferred
from stack.settings import scenarios
from stack.settings.run import RunConfig, in_scenario

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
) -> bool:
    """Run `plan` for the agents of `configs` (one per agent) into `out`, write the report, print
    the leaderboard; True when Ctrl-C cut it short (the scenarios run so far are reported, the
    journals kept for --resume)."""
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
    with deferred(interrupt_after=False):
        write_json(
            out / "summary.json",
            {
                "plan": asdict(plan),
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
    print(markdown(rows), end="")
    resumable = " (interrupted: the same command with --resume finishes it)"
    print(f"results: {out}" + (resumable if interrupted else ""))
    return interrupted
