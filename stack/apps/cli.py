"""`drivestack`: the command line. Parsing and one-line errors only; each sub-command's work lives in
its own module of `stack.apps` (or `stack.deepcars`), imported when the command runs."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, cast

import typer

from common.plugins import SPEC_FORMS
from stack.apps.benchmark_cli import benchmark
from stack.apps.commands import agents, controllers, ensemble, export, gate_calibrate, sweep, tracking, view
from stack.apps.folders import claimed, claimed_for, episodes_kept, resumed
from stack.apps.options import (
    AGAIN,
    JOBS_OPTION,
    PLANT_HELP,
    RAY_OPTION,
    RECORD_HELP,
    SET_HELP,
    TRAFFIC_HELP,
    TRAIN_CONFIG,
    TRAIN_RAY_HELP,
    VARIANT_HELP,
    VERSION_OPTION,
    chosen,
    configured,
    fail,
    guarded,
    listed,
    per_agent,
    population_option,
    ray_or_fail,
    rerun_or_fail,
    until_interrupted,
)
from stack.apps.plugin_checks import agent_name_or_fail, plugins_or_fail
from stack.apps.preflight import checked_run

PLUGIN_HELP = f"a plug-in class: {SPEC_FORMS} (docs/plugins.md)."
ADOPT_HELP = (
    "With --resume: take over a training folder made before folders recorded their owner, once its "
    "config.yaml agrees with the run's model files, checkpoint and summary."
)
RESUME_HELP = "Finish the interrupted run in --out (same arguments): its finished episodes are kept."

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="A hierarchical highway driving stack.",
)


def main() -> None:
    """The `drivestack` entry point (see `guarded`)."""
    guarded(app)


@app.callback()
def root(version: bool = VERSION_OPTION) -> None:
    """Perception grid -> decision agent -> lane-change controllers, closed-loop on highway-env."""


@app.command()
def run(
    config: Path | None = typer.Option(
        None, "--config", "-c", help="YAML run config (default: configs/highway.yaml)."
    ),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    agent: str | None = typer.Option(None, help=f"Decision agent (overrides planner.agent); {PLUGIN_HELP}"),
    model: Path | None = typer.Option(None, help="Model file of a learned agent (planner.model)."),
    controller: str | None = typer.Option(None, help=f"Controller (controller.type); {PLUGIN_HELP}"),
    episodes: int | None = typer.Option(None, help="Number of seeded episodes."),
    seed: int | None = typer.Option(None, help="Seed of the first episode."),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/run-<time>)."),
    video: bool = typer.Option(False, "--video", help="Save a GIF of the first episode."),
    backend: str | None = typer.Option(None, help="Simulation backend: vector | fast | stock (sim.backend)."),
    plant: str | None = typer.Option(None, help=PLANT_HELP),
    scenario: str | None = typer.Option(None, help="Named world (drivestack scenarios)."),
    traffic: str | None = typer.Option(None, help=TRAFFIC_HELP),
    jobs: int = JOBS_OPTION,
    ray: str | None = RAY_OPTION,
    progress: bool = typer.Option(True, help="Show a progress bar."),
    beside: str | None = typer.Option(None, help="Also run this agent on the same seeds, then both."),
    resume: bool = typer.Option(False, help=RESUME_HELP),
    record: bool = typer.Option(False, "--record", help=RECORD_HELP.format(item="episode")),
) -> None:
    """Run seeded closed-loop episodes and write a results folder."""
    rerun_or_fail("--record", record)
    agent_name_or_fail("--beside", beside)
    pairs = [(agent, model)] + ([(beside, None)] if beside is not None else [])
    cfgs = per_agent(
        config,
        sets,
        pairs,
        scenario=scenario,
        traffic=population_option(traffic),
        controller__type=controller,
        sim__backend=backend,
        sim__plant=plant,
        episodes=episodes,
        seed=seed,
    )
    if len(cfgs) > 1 and cfgs[1].planner.agent == cfgs[0].planner.agent:
        fail(f"--beside: expected an agent other than the run's own ({cfgs[0].planner.agent})")
    plugins_or_fail(cfgs, ["--agent" if agent else "planner.agent", "--beside"])
    ray_or_fail(ray)
    done = resumed(cfgs, out, "run") if resume else None
    folder = checked_run(cfgs, out, "run", resume, jobs)
    from stack.apps.run import run_and_report

    until_interrupted(
        lambda: run_and_report(cfgs, folder, video, jobs, progress, ray, done, record),
        lambda: episodes_kept(folder),
    )


@app.command()
def track(
    controller: str = typer.Option("all", help=f"Comma-separated names (all: every one) or {PLUGIN_HELP}"),
    plant: str = typer.Option("all", help="kinematic | dynamic | all (the built-in change runs kinematic)."),
    speeds: str = typer.Option(
        "3,5,10,15,20,25,30,35,40,20-5,3-15",
        help="Comma-separated speeds [m/s]: V (constant) or A-B (from A, the cruise set to B).",
    ),
    duration: float | None = typer.Option(None, help="Lane-change duration T [s] (controller config)."),
    config: Path | None = typer.Option(None, "--config", "-c", help="YAML config (controller section)."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/track-<time>)."),
    ray: str | None = RAY_OPTION,
    progress: bool = typer.Option(True, help="Show a progress bar."),
    record: bool = typer.Option(False, "--record", help=RECORD_HELP.format(item="maneuver")),
) -> None:
    """Single lane changes on empty straight and curved roads: tracking metrics and plots."""
    rerun_or_fail("--record", record)
    from records import PLANTS
    from stack.apps.track import controller_names, parse_speeds, track_and_report, warn_of_edited_plug_ins

    try:
        names = controller_names(",".join(listed("--controller", controller)))
    except ValueError as error:
        fail(f"--controller: {error}")
    plants = chosen("--plant", plant, PLANTS)
    try:
        speed_list = parse_speeds(speeds)
    except ValueError as error:
        fail(f"--speeds: {error}")
    cfg = configured(config, sets, controller__lane_change_duration_s=duration)
    ray_or_fail(ray)
    folder = claimed_for("track", out, f"{names}{plants}{speed_list}", cfg)
    warn_of_edited_plug_ins(names, cfg, folder)
    until_interrupted(
        lambda: track_and_report(names, speed_list, cfg, folder, progress, cast(Any, plants), ray, record),
        lambda: f"the table above holds every maneuver measured; {AGAIN}",
    )


@app.command()
def compare(
    agents: str = typer.Option("ddqn,rule,mobil,keep-lane", help=f"Comma-separated names or {PLUGIN_HELP}"),
    models: str = typer.Option("", help="Model files for learned agents: name=path,name=path."),
    config: Path | None = typer.Option(
        None, "--config", "-c", help="YAML run config (default: configs/highway.yaml)."
    ),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    episodes: int | None = typer.Option(None, help="Seeded episodes per agent."),
    seed: int | None = typer.Option(None, help="Seed of the first episode."),
    scenario: str | None = typer.Option(None, help="Named world (drivestack scenarios)."),
    traffic: str | None = typer.Option(None, help=TRAFFIC_HELP),
    baseline: str | None = typer.Option(None, help="Agent to report paired differences against."),
    plant: str | None = typer.Option(None, help=PLANT_HELP),
    jobs: int = JOBS_OPTION,
    ray: str | None = RAY_OPTION,
    out: Path | None = typer.Option(None, help="Results folder (default: runs/compare-<time>)."),
    resume: bool = typer.Option(False, help=RESUME_HELP),
    progress: bool = typer.Option(True, help="Show progress bars."),
    record: bool = typer.Option(False, "--record", help=RECORD_HELP.format(item="episode and agent")),
) -> None:
    """Every agent on the same seeded episodes: one table, one bar plot."""
    rerun_or_fail("--record", record)
    try:
        model_paths = dict(entry.split("=", 1) for entry in models.split(",") if entry)
    except ValueError:
        fail(f"--models: expected name=path[,name=path], got {models!r}")
    names = listed("--agents", agents)
    if len(set(names)) < len(names):
        fail(f"--agents: expected each agent once, got {agents!r}")
    if baseline is not None and baseline not in names:
        fail(f"--baseline: {baseline!r} is not among --agents ({', '.join(names)})")
    if unknown := [name for name in model_paths if name not in names]:
        fail(f"--models: {unknown[0]!r} is not among --agents ({', '.join(names)})")
    pairs = [(name, model_paths.get(name)) for name in names]
    configs = per_agent(
        config,
        sets,
        pairs,
        labels={"planner.agent": "--agents"},
        model_option="--models",
        scenario=scenario,
        traffic=population_option(traffic),
        sim__plant=plant,
        episodes=episodes,
        seed=seed,
    )
    plugins_or_fail(configs, ["--agents"] * len(configs))
    if baseline is not None:  # as the configs name it: a file plug-in by its absolute path
        baseline = configs[names.index(baseline)].planner.agent
    ray_or_fail(ray)
    done = resumed(configs, out, "compare") if resume else None
    folder = checked_run(configs, out, "compare", resume, jobs)
    from stack.apps.compare import compare_and_report

    until_interrupted(
        lambda: compare_and_report(configs, folder, jobs, progress, baseline, ray, done, record),
        lambda: episodes_kept(folder),
    )


@app.command()
def safety(
    scenario: str = typer.Option("all", help="lead-braking | cut-in | cut-out | all (docs/safety.md)."),
    agent: str | None = typer.Option(None, help=f"Decision agent (overrides planner.agent); {PLUGIN_HELP}"),
    controller: str | None = typer.Option(None, help=f"Controller (controller.type); {PLUGIN_HELP}"),
    plant: str | None = typer.Option(None, help=PLANT_HELP),
    quick: bool = typer.Option(False, "--quick", help="Coarse grids: all three types in a few minutes."),
    point: str | None = typer.Option(
        None, help="Replay one point of --scenario: NAME=VALUE,... (as printed)."
    ),
    video: bool = typer.Option(False, "--video", help="With --point: save the stack's drive as a GIF."),
    config: Path | None = typer.Option(None, "--config", "-c", help="YAML run config (its stack)."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/safety-<time>)."),
    jobs: int = JOBS_OPTION,
    ray: str | None = RAY_OPTION,
    progress: bool = typer.Option(True, help="Show a progress bar."),
    record: bool = typer.Option(
        False, "--record", help=RECORD_HELP.format(item="failure point (or --point)")
    ),
) -> None:
    """UN R157-style safety assessment: lead braking, cut-in, cut-out grids against the careful driver."""
    rerun_or_fail("--record", record)
    from stack.sim.safety_scenarios import SCENARIO_KINDS, parse_point

    kinds = cast(Any, chosen("--scenario", scenario, SCENARIO_KINDS))
    if video and point is None:
        fail("--video: replays one point; name it with --point")
    chosen_point = None
    if point is not None:
        if len(kinds) != 1:
            fail("--point: name one --scenario (lead-braking, cut-in or cut-out) for the point")
        try:
            chosen_point = parse_point(kinds[0], point)
        except ValueError as error:
            fail(f"--point: {error}")
    cfg = configured(config, sets, planner__agent=agent, controller__type=controller, sim__plant=plant)
    if cfg.highway.lanes_count < 3:
        fail(f"highway.lanes_count: the safety scenarios need 3 or more lanes, got {cfg.highway.lanes_count}")
    plugins_or_fail([cfg], ["--agent" if agent else "planner.agent"])
    from stack.runs.kept import build_agent

    try:
        build_agent(cfg, cfg.seed)
    except ValueError as error:
        fail(str(error))
    ray_or_fail(ray)
    from stack.apps.training import check_jobs

    check_jobs(jobs)
    folder = claimed_for("safety", out, f"{kinds}{quick}{point}{video}", cfg)
    from stack.apps.safety import assess_and_report, replay

    if chosen_point is not None:
        until_interrupted(lambda: replay(cfg, chosen_point, video, folder, record))
    else:
        until_interrupted(lambda: assess_and_report(cfg, kinds, quick, folder, jobs, progress, ray, record))


@app.command()
def scenarios() -> None:
    """The named worlds `--scenario` takes, one line each."""
    from stack.worlds import scenarios as named

    for name in named.names():
        typer.echo(f"{name:12} {named.description(name)}")


reproduce_app = typer.Typer(no_args_is_help=True, help="Reproduce the paper's experiments.")
app.add_typer(reproduce_app, name="reproduce")
app.command()(export)
app.command()(ensemble)
app.command("gate-calibrate")(gate_calibrate)
app.command()(tracking)
app.command()(agents)
app.command()(controllers)
app.command()(sweep)
app.command()(view)
app.command()(benchmark)


@reproduce_app.command("deepcars")
def reproduce_deepcars(
    quick: bool = typer.Option(False, "--quick", help="Small budgets: every row in under 2 minutes."),
    variant: str = typer.Option("paper", help=VARIANT_HELP),
    seed: int = typer.Option(0, help="Seed of training and evaluation."),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/deepcars-<time>)."),
) -> None:
    """The paper's DeepCars table: tabular Q-learning, DQN and DDQN per network size, baselines."""
    from records import SEED_LIMIT
    from stack.apps.reproduce import reproduce_and_report
    from stack.deepcars.spec import VARIANTS

    variants = chosen("--variant", variant, VARIANTS)
    largest = SEED_LIMIT - 1_000_000
    if not 0 <= seed <= largest:
        fail(f"--seed: expected 0 to {largest} (its streams add up to 10,000 to it), got {seed}")
    folder = claimed_for("reproduce deepcars", out, f"{quick}{variants}{seed}")
    until_interrupted(lambda: reproduce_and_report(folder, quick, seed, variants))


@app.command()
def train(
    agent: str | None = typer.Option(None, help="ddqn | dqn | tabular (overrides train.algorithm)."),
    config: Path | None = typer.Option(
        None, "--config", "-c", help="YAML training config (default: configs/train/ddqn.yaml)."
    ),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    steps: int | None = typer.Option(None, help="Total environment steps (train.steps)."),
    envs: int | None = typer.Option(None, help="Environments in parallel processes (train.envs)."),
    worlds: int | None = typer.Option(
        None,
        help="Worlds stepped together as one batched env (train.worlds): in this process, or split "
        "over --envs processes (train.envs 1 unless --envs is given).",
    ),
    plant: str | None = typer.Option(None, help=PLANT_HELP),
    seed: int | None = typer.Option(None, help="Training seed."),
    scenario: str | None = typer.Option(None, help="Named world to train in (drivestack scenarios)."),
    traffic: str | None = typer.Option(None, help=TRAFFIC_HELP),
    out: Path | None = typer.Option(None, help="Run folder (default: runs/train-<time>)."),
    resume: Path | None = typer.Option(
        None, help="Continue the run in this folder from its last checkpoint."
    ),
    adopt: bool = typer.Option(False, "--adopt", help=ADOPT_HELP),
    ray: str | None = typer.Option(None, "--ray", metavar="[ADDRESS]", help=TRAIN_RAY_HELP),
    progress: bool = typer.Option(True, help="Show a progress bar."),
) -> None:
    """Train a decision agent inside the closed loop, keeping the best model by real-time validation
    (train.members N > 1: N seeds one after the other, then their ensemble; the default config: 3)."""
    from stack.apps.members import check_unfinished, train_members
    from stack.apps.training import (
        check_batched,
        check_envs,
        check_init_model,
        check_memory,
        check_ray_shards,
        resumed_training,
        train_or_fail,
        training_owner,
    )

    if resume is not None:
        given = {"--agent": agent, "--config": config, "--envs": envs, "--worlds": worlds, "--seed": seed}
        given |= {"--plant": plant}
        given |= {"--scenario": scenario, "--traffic": traffic, "--out": out}
        cfg = resumed_training(resume, sets, steps, given, adopt)
        if cfg.train.members > 1:
            check_unfinished(resume, cfg)
    elif adopt:
        fail("--adopt: has no effect without --resume DIR (it takes over a folder made before owner records)")
    else:
        options: dict[str, object] = {"scenario": scenario, "train__algorithm": agent, "seed": seed}
        options |= {"train__envs": envs, "traffic": population_option(traffic)}
        options |= {"train__worlds": worlds} | ({"train__envs": 1} if worlds and envs is None else {})
        cfg = configured(config or TRAIN_CONFIG, sets, None, train__steps=steps, sim__plant=plant, **options)
    check_memory(cfg)
    if ray in (None, "local"):
        check_envs(cfg)
    check_batched(cfg)
    check_ray_shards(cfg, ray)
    if not cfg.train.scenarios:
        try:
            cfg.check_one_encoding({cfg.scenario or "highway": cfg.highway}, "perception.lanes")
        except ValueError as error:
            fail(str(error))
    check_init_model(cfg)
    owner, resuming = training_owner(cfg), resume is not None
    folder = claimed(resume or out, f"train-{cfg.train.algorithm}", owner, resuming, restart=False)
    if (train_members if cfg.train.members > 1 else train_or_fail)(cfg, folder, progress, ray):
        sys.exit(130)
