"""`drivestack benchmark`'s options: parsing and one-line errors only, like `stack.apps.cli`, which
registers it; the work is `stack.apps.benchmark`."""

from __future__ import annotations

from pathlib import Path

import typer

from common.plugins import SPEC_FORMS
from stack.apps.options import (
    JOBS_OPTION,
    PLANT_HELP,
    RAY_OPTION,
    SET_HELP,
    TRAFFIC_HELP,
    fail,
    listed,
    per_agent,
    populations_option,
    ray_or_fail,
)

BENCHMARK_AGENTS = "keep-lane,rule,mobil,ddqn,lookahead"
REPORT_SEED = 970_000


def benchmark(
    agents: str = typer.Option(
        BENCHMARK_AGENTS, help=f"Comma-separated names or a plug-in class: {SPEC_FORMS} (docs/plugins.md)."
    ),
    models: str = typer.Option("", help="Model files for learned agents: name=path,name=path."),
    quick: bool = typer.Option(False, "--quick", help="4 episodes a scenario (minutes, not hours)."),
    episodes: int | None = typer.Option(
        None, min=1, help="Episodes per scenario, random included (replaces the plan's 500 / 300)."
    ),
    seed: int = typer.Option(REPORT_SEED, min=0, help="Seed of each scenario's first episode."),
    duration: float | None = typer.Option(
        None, min=1.0, max=600.0, hidden=True, help="Smoke tests: episode length [s]."
    ),
    config: Path | None = typer.Option(
        None, "--config", "-c", help="YAML run config (default: configs/highway.yaml); its world is replaced."
    ),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    plant: str | None = typer.Option(None, help=PLANT_HELP),
    traffic: str | None = typer.Option(
        None, help=TRAFFIC_HELP + " Several names (A,B,...): a traffic axis, the benchmark under each."
    ),
    jobs: int = JOBS_OPTION,
    ray: str | None = RAY_OPTION,
    out: Path | None = typer.Option(None, help="Results folder (default: runs/benchmark-<time>)."),
    resume: bool = typer.Option(False, help="Finish the interrupted benchmark in --out (same arguments)."),
    progress: bool = typer.Option(True, help="Show progress bars."),
) -> None:
    """Every agent on every named scenario on fixed report seeds: one score and one table per agent."""
    names = listed("--agents", agents)
    if len(set(names)) < len(names):
        fail(f"--agents: expected each agent once, got {agents!r}")
    try:
        model_paths = dict(entry.split("=", 1) for entry in models.split(",") if entry)
    except ValueError:
        fail(f"--models: expected name=path[,name=path], got {models!r}")
    if unknown := [name for name in model_paths if name not in names]:
        fail(f"--models: {unknown[0]!r} is not among --agents ({', '.join(names)})")
    if resume and out is None:
        fail("--resume: name the folder of the interrupted benchmark with --out")
    from stack.runtime.files import JOURNAL

    if resume and out is not None and out.is_dir() and not any(out.glob(f"*/*.{JOURNAL}")):
        fail(f"--resume: {out} holds no unfinished episodes (no journal); nothing to resume")
    from stack.apps.benchmark import BenchmarkPlan

    plan = BenchmarkPlan.chosen(quick, episodes, seed, duration)
    populations = {
        str(population): per_agent(
            config,
            sets,
            [(name, model_paths.get(name)) for name in names],
            labels={"planner.agent": "--agents", "traffic": "--traffic"},
            model_option="--models",
            traffic=population,
            sim__plant=plant,
            episodes=plan.episodes,
            seed=seed,
        )
        for population in populations_option(traffic)
    }
    configs = [config for configs in populations.values() for config in configs]
    from stack.apps.plugin_checks import plugins_or_fail
    from stack.apps.preflight import checked_run

    plugins_or_fail(configs, ["--agents"] * len(configs))
    ray_or_fail(ray)
    folder = checked_run(configs, out, "benchmark", resume, jobs)
    from stack.apps.benchmark import run_benchmark, run_traffic_axis
    from stack.apps.options import until_interrupted

    if len(populations) > 1:
        until_interrupted(
            lambda: run_traffic_axis(populations, plan, folder, jobs, progress, ray, resume),
            lambda: f"the episodes finished are kept in {folder}'s population folders; --resume finishes it",
        )
        return
    until_interrupted(
        lambda: run_benchmark(configs, plan, folder, jobs, progress, ray, resume)[0],
        lambda: f"the episodes finished are kept in {folder}'s scenario folders; --resume finishes it",
    )
