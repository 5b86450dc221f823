"""Where `drivestack benchmark`'s time goes: a reduced benchmark (a few episodes a scenario, fresh
seeds) run in this process through `stack.apps.benchmark.run_benchmark`, with each agent's run of
each scenario, the journal writes, the worlds' allowances, the reports (comparison.json/png per
scenario, summary, benchmark.csv, leaderboard.png) and the process pools started timed as they
happen.

    .venv/bin/python benchmarks/benchmark_time.py [--episodes 8] [--jobs 2] [--seed 1007000]
                                                  [--agents keep-lane,rule,mobil,ddqn,lookahead]

Prints wall time per agent and per scenario, how each agent's episodes were stepped (`batched`:
its scenario's worlds in batches, `per-world`: one world at a time, with the reason), and the full
benchmark's time extrapolated from the per-episode times: each (agent, scenario)'s wall per episode
x the full plan's episodes (500 a scenario, 300 of `random`) over the same `--jobs`, the worlds'
allowances at one reset a seed (timed on 20 `dense` seeds here, over `--jobs` processes), plus the
once-per-benchmark costs. Batched worlds get cheaper per episode in larger batches, so the
extrapolation is an upper bound for the batched agents. The benchmark's pool of `--jobs` workers
is started first, alone (spawned interpreters importing the stack), and timed: the benchmark then
runs on it, as it does on the pool it starts itself.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import stack.apps.benchmark as benchmark
import stack.apps.compare as compare_module
from stack.apps.benchmark import FULL_EPISODES, FULL_RANDOM_EPISODES, RANDOM, BenchmarkPlan, run_benchmark
from stack.apps.benchmark_cli import BENCHMARK_AGENTS
from stack.apps.benchmark_report import combined
from stack.apps.options import per_agent
from stack.runs.statistics import Interval, mean_interval
from stack.runs.world_allowance import world_allowance
from stack.runtime import executors
from stack.runtime.files import EpisodeJournal

spent: dict[str, float] = defaultdict(float)
"""Wall time [s] by part: `run AGENT SCENARIO`, `journal` and the functions of `REPORTS`."""
stepping: dict[tuple[str, str], str] = {}
"""How each (agent, scenario) was stepped."""
pools_started = [0]
REPORTS = (
    "allowances_of",
    "started",
    "write_comparison",
    "leaderboard",
    "csv_rows",
    "write_csv",
    "write_json",
    "plot_leaderboard",
)
"""What `run_benchmark` calls around the episodes, each timed."""


def timed(part: Callable[[Any], str], function: Callable[..., Any]) -> Callable[..., Any]:
    """`function`, adding its wall time to `spent[part(first argument)]`."""

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            spent[part(args[0] if args else None)] += time.perf_counter() - start

    return wrapper


def instrument() -> None:
    """Wrap what the benchmark calls so its parts are timed (the results are untouched)."""
    run = compare_module.run

    def timed_run(config: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        results = run(config, **kwargs)
        key = (config.planner.agent, config.scenario)
        spent[f"run {key[0]} {key[1]}"] += time.perf_counter() - start
        reason = results.summary.get("stepping_reason")
        stepping[key] = results.summary["stepping"] + (f" ({reason})" if reason else "")
        return results

    compare_module.run = timed_run
    EpisodeJournal.record = timed(lambda _: "journal", EpisodeJournal.record)  # type: ignore[method-assign]
    for name in REPORTS:
        setattr(benchmark, name, timed(lambda _, name=name: name, getattr(benchmark, name)))
    pool = executors._pool

    def counted_pool(workers: int) -> Any:
        before = None if executors._kept_pools is None else executors._kept_pools.get(workers)
        made = pool(workers)
        pools_started[0] += made is not before
        return made

    executors._pool = counted_pool


def warm_worker(_: int) -> int:
    """What a pool worker imports before its first episode."""
    import stack.runs.batch_episodes  # noqa: F401
    import stack.runs.episodes  # noqa: F401

    return os.getpid()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--agents", default=BENCHMARK_AGENTS)
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1_007_000)
    parser.add_argument("--duration", type=float, default=None, help="episode length [s] (smoke tests)")
    parser.add_argument("--out", type=Path, default=None, help="keep the benchmark's folder here")
    parser.add_argument("--scores-of", type=Path, default=None, help="only print a finished folder's scores")
    args = parser.parse_args()
    if args.scores_of is not None:
        print(separation(args.scores_of), end="")
        return
    agents = args.agents.split(",")
    instrument()
    plan = BenchmarkPlan.chosen(False, args.episodes, args.seed, args.duration)
    configs = per_agent(
        None, [], [(name, None) for name in agents], labels={}, model_option="--models", seed=args.seed
    )
    with tempfile.TemporaryDirectory() as scratch, executors.shared_workers():
        out = args.out or Path(scratch) / "benchmark"
        out.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        if args.jobs > 1:
            list(executors.completed(warm_worker, list(range(args.jobs)), args.jobs))
        start_up = time.perf_counter() - start
        run_benchmark(configs, plan, out, jobs=args.jobs, progress=False)
        total = time.perf_counter() - start
        scores = separation(out)
    report(agents, plan, args, total, start_up, allowance_s(configs[0], plan))
    print("\n" + scores, end="")


def separation(folder: Path) -> str:
    """The score and the set-speed score of each agent of the benchmark in `folder`, best first,
    and the paired difference of each agent to the next (per scenario, on the same seeds, combined
    over the scenarios as the overall score is): how far apart each score puts them."""
    rows = list(csv.DictReader((folder / "benchmark.csv").open()))
    order = [row["agent"] for row in json.loads((folder / "summary.json").read_text())["leaderboard"]]
    scenarios = list(dict.fromkeys(row["scenario"] for row in rows))
    found = {(r["agent"], r["scenario"], r["seed"]): r for r in rows}
    lines = ["| agent | score | set-speed score | progress |", "|---|---|---|---|"]
    for agent in order:
        cells = [
            combined(
                [
                    mean_interval(
                        [float(r[name]) for r in rows if r["agent"] == agent and r["scenario"] == s]
                    )
                    for s in scenarios
                ]
            )
            for name in ("score", "set_speed_score", "progress")
        ]
        lines.append(f"| {agent} | " + " | ".join(_cell(c) for c in cells) + " |")
    lines += [
        "",
        "| pair (paired by seed) | score difference | set-speed score difference | apart (new / old) |",
        "|---|---|---|---|",
    ]
    for better, worse in zip(order, order[1:], strict=False):
        cells, apart = [], []
        for name in ("score", "set_speed_score"):
            per = [
                mean_interval(
                    [
                        float(found[better, s, seed][name]) - float(found[worse, s, seed][name])
                        for (a, sc, seed) in found
                        if a == better and sc == s and (worse, s, seed) in found
                    ]
                )
                for s in scenarios
            ]
            cells.append(_cell(combined(per, floor=-math.inf), signed=True))
            apart.append(sum(part.low > 0 or part.high < 0 for part in per))
        lines.append(
            f"| {better} - {worse} | {cells[0]} | {cells[1]} | {apart[0]} / {apart[1]} of {len(scenarios)} |"
        )
    return "\n".join(lines) + "\n"


def _cell(interval: Interval, signed: bool = False) -> str:
    form = "+.3f" if signed else ".3f"
    return f"{interval.value:{form}} [{interval.low:{form}}, {interval.high:{form}}]"


def allowance_s(config: Any, plan: BenchmarkPlan, seeds: int = 20) -> float:
    """Wall time [s] of one seed's `world_allowance` on `dense`, its env made beforehand."""
    moved = plan.configs([config], "dense")[0]
    world_allowance(moved, plan.seed)
    start = time.perf_counter()
    for seed in range(plan.seed + 1, plan.seed + 1 + seeds):
        world_allowance(moved, seed)
    return (time.perf_counter() - start) / seeds


def report(
    agents: list[str],
    plan: BenchmarkPlan,
    args: argparse.Namespace,
    total: float,
    start_up: float,
    per_seed_s: float,
) -> None:
    """The tables: per agent, per scenario and agent, around the episodes, the extrapolation."""
    runs = {key: spent[f"run {key[0]} {key[1]}"] for key in stepping}
    machine = platform.processor() or platform.machine()
    print(f"{machine}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    print(
        f"benchmark of {','.join(agents)}: {args.episodes} episodes a scenario from seed {args.seed}, "
        f"--jobs {args.jobs}: {total:.1f} s wall"
    )
    print("\n| agent | wall s | share | s / episode | stepping |")
    print("|---|---|---|---|---|")
    for agent in agents:
        wall = sum(value for (name, _), value in runs.items() if name == agent)
        ways = sorted({stepping[key] for key in stepping if key[0] == agent})
        per = wall / (args.episodes * len(plan.scenarios))
        print(f"| {agent} | {wall:.1f} | {wall / total:.0%} | {per:.3f} | {'; '.join(ways)} |")
    print("\n| scenario | " + " | ".join(agents) + " |")
    print("|---|" + "---|" * len(agents))
    for scenario in plan.scenarios:
        cells = [f"{runs.get((agent, scenario), 0.0):.1f}" for agent in agents]
        print(f"| {scenario} | " + " | ".join(cells) + " |")
    ran = sum(runs.values())
    around = {name: spent[name] for name in REPORTS}
    rest = total - start_up - ran - sum(around.values())
    print(
        f"\npool start-up {start_up:.1f} s ({pools_started[0]} pools started); episodes {ran:.1f} s "
        f"(of which journal writes {spent['journal']:.1f} s); "
        + "; ".join(f"{name} {value:.1f} s" for name, value in around.items())
        + f"; the rest {rest:.1f} s"
    )
    full = {
        scenario: FULL_RANDOM_EPISODES if scenario == RANDOM else FULL_EPISODES for scenario in plan.scenarios
    }
    scale = {scenario: full[scenario] / args.episodes for scenario in plan.scenarios}
    episodes_full = sum(wall * scale[scenario] for (_, scenario), wall in runs.items())
    allowances_full = per_seed_s * sum(full.values()) / max(args.jobs, 1)
    fixed = total - ran - around["allowances_of"]
    estimate = episodes_full + allowances_full + fixed
    print(
        f"full benchmark ({sum(full.values())} episodes an agent) extrapolated: {estimate / 60:.1f} min "
        f"(episodes {episodes_full / 60:.1f} min, allowances {allowances_full:.0f} s at "
        f"{1000 * per_seed_s:.1f} ms a seed, the rest {fixed:.0f} s)"
    )


if __name__ == "__main__":
    main()
