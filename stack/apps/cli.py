"""`drivestack`: the command line."""

from __future__ import annotations

import sys
from datetime import datetime
from functools import partial
from pathlib import Path

import typer
from rich.console import Console

from stack.core.config import ConfigError, load_config

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_show_locals=False,
    help="A hierarchical highway driving stack.",
)
DEFAULT_CONFIG = Path("configs/highway.yaml")


def fail(message: str) -> None:
    Console(stderr=True).print(f"[red]error:[/red] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(code=2)


def check_agent(cfg) -> None:
    """Build the configured agent once, so a missing or unsafe model file fails before any work."""
    from planner.factory import make_agent
    from stack.core.closed_loop import grid_config

    try:
        make_agent(cfg.planner.agent, cfg.highway.lanes_count, grid_config(cfg), cfg.seed, cfg.planner.model)
    except ValueError as error:
        fail(str(error))


def fresh_run_dir(prefix: str) -> Path:
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S-%f")
    return Path("runs") / f"{prefix}-{stamp}"


@app.callback()
def main() -> None:
    """Perception grid -> decision agent -> lane-change controllers, closed-loop on highway-env."""


@app.command()
def run(
    config: Path = typer.Option(DEFAULT_CONFIG, "--config", "-c", help="YAML run config."),
    agent: str | None = typer.Option(None, help="Decision agent (overrides planner.agent)."),
    model: Path | None = typer.Option(None, help="Model file of a learned agent (planner.model)."),
    controller: str | None = typer.Option(None, help="Controller (overrides controller.type)."),
    episodes: int | None = typer.Option(None, help="Number of seeded episodes."),
    seed: int | None = typer.Option(None, help="Seed of the first episode."),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/run-<time>)."),
    video: bool = typer.Option(False, "--video", help="Save a GIF of the first episode."),
    backend: str | None = typer.Option(None, help="Simulation backend: fast | stock (sim.backend)."),
    jobs: int = typer.Option(1, min=1, help="Parallel processes for the episodes."),
    progress: bool = typer.Option(True, help="Show a progress bar."),
) -> None:
    """Run seeded closed-loop episodes and write a results folder."""
    try:
        cfg = load_config(
            config,
            planner__agent=agent,
            planner__model=model,
            controller__type=controller,
            sim__backend=backend,
            episodes=episodes,
            seed=seed,
        )
    except ConfigError as error:
        fail(str(error))
    check_agent(cfg)
    from stack.apps.report import print_tables, write_results
    from stack.core.episodes import run as run_loop

    out = out or fresh_run_dir("run")
    try:
        results = run_loop(cfg, video=video, progress=progress, jobs=jobs)
    except KeyboardInterrupt:
        fail("interrupted before the first episode finished; nothing to write")
    write_results(out, results.summary, results.episodes, results.frames)
    print_tables(results.summary, results.episodes)
    Console().print(f"results: {out}")
    if results.summary["interrupted"]:
        sys.exit(130)


@app.command()
def track(
    controller: str = typer.Option("all", help="pid | mpc | builtin | all"),
    speeds: str = typer.Option("15,20,25,30", help="Comma-separated speeds [m/s]."),
    duration: float | None = typer.Option(None, help="Lane-change duration T [s] (controller config)."),
    config: Path = typer.Option(DEFAULT_CONFIG, "--config", "-c", help="YAML config (controller section)."),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/track-<time>)."),
    progress: bool = typer.Option(True, help="Show a progress bar."),
) -> None:
    """Single lane changes on empty straight and curved roads: tracking metrics and plots."""
    from stack.apps.track import PLANTS, ROADS, TRACK_CONTROLLERS

    names = list(TRACK_CONTROLLERS) if controller == "all" else controller.split(",")
    unknown = [name for name in names if name not in TRACK_CONTROLLERS]
    if unknown:
        fail(f"--controller: unknown {unknown[0]!r}; available: {', '.join(TRACK_CONTROLLERS)}, all")
    try:
        speed_list = [float(value) for value in speeds.split(",")]
    except ValueError:
        fail(f"--speeds: expected comma-separated numbers in m/s, got {speeds!r}")
    if not all(0 < v <= 40 for v in speed_list):
        fail(f"--speeds: every speed must be in (0, 40] m/s, got {speeds}")
    try:
        cfg = load_config(config, controller__lane_change_duration_s=duration)
    except ConfigError as error:
        fail(str(error))
    from tqdm import tqdm

    from stack.apps.track import track as run_track

    out = out or fresh_run_dir("track")
    total = len(ROADS) * len(speed_list) * 2 * sum(1 if n == "builtin" else len(PLANTS) for n in names)
    with tqdm(total=total, unit="maneuver", disable=not progress) as bar:
        maneuvers = run_track(
            names,
            speed_list,
            cfg.controller.lane_change_duration_s,
            cfg.controller,
            out,
            cfg.dt,
            progress=lambda: bar.update(1),
        )
    print_tracking(maneuvers)
    Console().print(f"results: {out}")


def _mean(group: list, field: str) -> float:
    values = [getattr(m, field) for m in group if getattr(m, field) is not None]
    return sum(values) / len(values) if values else float("nan")


def print_tracking(maneuvers) -> None:
    from rich.table import Table

    table = Table(title="lane changes (left / right averaged)")
    for column in (
        "controller",
        "road",
        "plant",
        "speed",
        "duration s",
        "overshoot cm",
        "RMS cm",
        "max cm",
        "peak a_y",
        "peak jerk",
        "solve p95 ms",
        "fallbacks",
    ):
        table.add_column(column, justify="right")
    groups: dict = {}
    for m in maneuvers:
        groups.setdefault((m.controller, m.road, m.plant, m.speed), []).append(m)
    for (name, road, plant, speed), group in groups.items():
        mean = partial(_mean, group)
        table.add_row(
            name,
            road,
            plant,
            f"{speed:g}",
            f"{mean('duration_s'):.2f}",
            f"{100 * mean('overshoot_m'):.1f}",
            f"{100 * mean('rms_error_m'):.2f}",
            f"{100 * mean('max_error_m'):.1f}",
            f"{mean('peak_lat_accel'):.2f}",
            f"{mean('peak_lat_jerk'):.2f}",
            f"{max(m.solve_ms_p95 for m in group):.2f}",
            str(sum(m.fallbacks for m in group)),
        )
    Console(width=160).print(table)


@app.command()
def compare(
    agents: str = typer.Option("ddqn,rule,mobil,keep-lane", help="Comma-separated agent names."),
    models: str = typer.Option("", help="Model files for learned agents: name=path,name=path."),
    config: Path = typer.Option(DEFAULT_CONFIG, "--config", "-c", help="YAML run config."),
    episodes: int | None = typer.Option(None, help="Seeded episodes per agent."),
    seed: int | None = typer.Option(None, help="Seed of the first episode."),
    jobs: int = typer.Option(1, min=1, help="Parallel processes for the episodes."),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/compare-<time>)."),
    progress: bool = typer.Option(True, help="Show progress bars."),
) -> None:
    """Every agent on the same seeded episodes: one table, one bar plot."""
    try:
        model_paths = dict(entry.split("=", 1) for entry in models.split(",") if entry)
    except ValueError:
        fail(f"--models: expected name=path[,name=path], got {models!r}")
    names = [name for name in agents.split(",") if name]
    try:
        configs = [
            load_config(
                config,
                planner__agent=name,
                planner__model=model_paths.get(name),
                episodes=episodes,
                seed=seed,
            )
            for name in names
        ]
    except ConfigError as error:
        fail(str(error))
    for cfg in configs:
        check_agent(cfg)
    from stack.apps.compare import compare as run_compare
    from stack.apps.compare import markdown, write_comparison

    out = out or fresh_run_dir("compare")
    summaries = run_compare(configs, jobs=jobs, progress=progress)
    write_comparison(summaries, out)
    Console().print(markdown(summaries), highlight=False)
    Console().print(f"results: {out}")


reproduce_app = typer.Typer(no_args_is_help=True, help="Reproduce the paper's experiments.")
app.add_typer(reproduce_app, name="reproduce")


@reproduce_app.command("deepcars")
def reproduce_deepcars(
    quick: bool = typer.Option(False, "--quick", help="Small budgets: every row in under 2 minutes."),
    seed: int = typer.Option(0, help="Seed of training and evaluation."),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/deepcars-<time>)."),
) -> None:
    """The paper's DeepCars table: tabular Q-learning, DQN and DDQN per network size, baselines."""
    from stack.deepcars.reproduce import reproduce

    out = out or fresh_run_dir("deepcars")
    console = Console()
    with console.status("reproducing DeepCars") as status:
        reproduce(out, quick=quick, seed=seed, progress=lambda name: status.update(f"done: {name}"))
    console.print((out / "results.md").read_text(), highlight=False)
    console.print(f"results: {out}")


@app.command()
def train(
    agent: str | None = typer.Option(None, help="ddqn | dqn | tabular (overrides train.algorithm)."),
    config: Path = typer.Option(
        Path("configs/train/ddqn.yaml"), "--config", "-c", help="YAML training config."
    ),
    steps: int | None = typer.Option(None, help="Total environment steps (train.steps)."),
    seed: int | None = typer.Option(None, help="Training seed."),
    out: Path | None = typer.Option(None, help="Run folder (default: runs/train-<time>)."),
    resume: Path | None = typer.Option(
        None, help="Continue the run in this folder from its last checkpoint."
    ),
    progress: bool = typer.Option(True, help="Show a progress bar."),
) -> None:
    """Train a decision agent inside the closed loop, keeping the best model by real-time validation."""
    try:
        if resume is not None:
            if not (resume / "config.yaml").is_file():
                fail(f"{resume}: not a training run folder (no config.yaml)")
            cfg = load_config(resume / "config.yaml", train__steps=steps)
        else:
            cfg = load_config(config, train__algorithm=agent, train__steps=steps, seed=seed)
    except ConfigError as error:
        fail(str(error))
    from stack.apps.train import Trainer

    folder = resume or out or fresh_run_dir(f"train-{cfg.train.algorithm}")
    summary = Trainer(cfg, folder, progress=progress).run()
    best = summary["best_validation"]
    Console().print(
        f"{summary['algorithm']}: {summary['steps']} steps in {summary['wall_time_s']:.0f} s; "
        + (
            f"best validation at step {best['step']}: collision rate {best['collision_rate']:.1%}, "
            f"mean return {best['mean_return']:.2f}, mean speed {best['mean_speed']:.2f} m/s"
            if best
            else "no validation yet"
        )
    )
    Console().print(
        f"run folder: {folder}" + (" (interrupted: resume with --resume)" if summary["interrupted"] else "")
    )
    if summary["interrupted"]:
        sys.exit(130)
