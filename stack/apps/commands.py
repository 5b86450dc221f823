"""The `drivestack` commands that do not run episodes here: `sweep` (training runs on Ray Tune),
`export`, `ensemble`, `view` (rerun's viewer on recordings), and the `agents` and `controllers` listings.
Parsing and one-line errors only, like `stack.apps.cli`, which registers them."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console

from common.plugins import AGENT_GROUP, SPEC_FORMS
from stack.apps.folders import claimed_for
from stack.apps.options import (
    AGAIN,
    SET_HELP,
    TRAIN_CONFIG,
    fail,
    listed,
    per_agent,
    ray_or_fail,
    until_interrupted,
)
from stack.apps.plugin_checks import plugins_or_fail

SWEEP_RAY_HELP = (
    "Where the trials run: a local Ray instance (default), auto (the cluster `ray start` made) or HOST:PORT."
)


def sweep(
    config: Path | None = typer.Option(
        None, "--config", "-c", help="The sweep file (YAML): base training config, search space, metric."
    ),
    out: Path | None = typer.Option(None, help="Sweep folder (default: runs/sweep-<time>)."),
    resume: Path | None = typer.Option(None, help="Continue the interrupted sweep in this folder."),
    ray: str | None = typer.Option(None, "--ray", metavar="[ADDRESS]", help=SWEEP_RAY_HELP),
    progress: bool = typer.Option(True, help="Show Ray Tune's progress table."),
) -> None:
    """Training runs over a grid or random space of seeds, hyper-parameters, scenarios (Ray Tune)."""
    if (config is None) == (resume is None):
        fail("sweep: expected --config SWEEP.yaml for a new sweep or --resume DIR to continue one")
    if resume is not None and out is not None:
        fail("--out: has no effect with --resume; the sweep goes on in its own folder")
    from stack.apps.training import check_init_model, check_memory
    from stack.settings.run import ConfigError
    from stack.settings.sweep import SWEEP_FILE, load_sweep

    spec = resume / SWEEP_FILE if resume is not None else config or Path(SWEEP_FILE)
    if resume is not None and not spec.is_file():
        fail(f"--resume: {resume} is not a sweep folder (no {SWEEP_FILE})")
    try:
        sweep_file, base, trials = load_sweep(spec)
    except ConfigError as error:
        fail(str(error))
    for trial in trials:
        check_memory(trial)
        check_init_model(trial)
    from stack.apps.folders import claimed, location
    from stack.runtime.owner import Owner, refusal

    folder, owner = location(resume or out, "sweep"), Owner("sweep", "")
    if why := refusal(folder, owner, resume is not None, restart=False):
        fail(why)
    envs = max(trial.train.envs for trial in trials)
    if ray in (None, "local"):
        from stack.runtime.machine import usable_cpus

        trial_cpus_or_fail(envs, usable_cpus(), "this machine")
    ray_or_fail(ray or "local")
    if ray not in (None, "local"):
        trial_cpus_or_fail(envs, largest_node_cpus(), "the largest Ray node")
    folder = claimed(folder, "sweep", owner, resume is not None, restart=False)
    from stack.apps.sweep import sweep_and_report

    until_interrupted(
        lambda: sweep_and_report(sweep_file, base, folder, resume is not None, progress),
        lambda: (
            f"the trials finished are kept: free space, then `drivestack sweep --resume {folder}`"
            if (folder / SWEEP_FILE).is_file()
            else AGAIN
        ),
    )


def trial_cpus_or_fail(envs: int, cpus: float, where: str) -> None:
    """Refuse, before any trial, trials that step more environments (one CPU each) than `where`
    has CPUs (`cpus`): Ray Tune would wait for them forever."""
    if envs > cpus:
        fail(
            f"train.envs: a trial steps {envs} environments, one CPU each, but {where} has {cpus:g} "
            "CPUs; no trial would ever start"
        )


def largest_node_cpus() -> float:
    """The CPUs of the largest live node of the connected Ray cluster."""
    import ray

    return max((node["Resources"].get("CPU", 0) for node in ray.nodes() if node.get("Alive")), default=0)


def export(
    model: Path = typer.Argument(..., help="A DDQN or DQN model file (.npz, from drivestack train)."),
    sb3: Path = typer.Option(..., "--sb3", help="The stable-baselines3 zip to write."),
) -> None:
    """Write a model file as a stable-baselines3 zip that `DQN.load` opens."""
    from stack.apps.folders import check_destination

    try:
        check_destination(sb3)
        from stack.apps.export import export_sb3

        written, metadata = export_sb3(model, sb3)
    except ValueError as error:
        fail(str(error))
    Console().print(
        f"wrote {written}: stable_baselines3.DQN.load({str(written)!r})", highlight=False, soft_wrap=True
    )
    if metadata.mobil_prior:
        Console().print(
            f"note: the zip's DQN.predict decides on the bare Q-values; drivestack adds "
            f"{metadata.mobil_prior:g} to the lane change MOBIL proposes (mobil_prior)",
            highlight=False,
        )
    if metadata.action_mask:
        Console().print(
            "note: the zip's observations end with the safety layer's 3 permitted commands (1 / 0); "
            "its DQN.predict may pick a refused one, drivestack picks among the permitted only",
            highlight=False,
        )


def ensemble(
    models: list[Path] = typer.Argument(..., help="2-16 DDQN or DQN model files of one grid and network."),
    out: Path = typer.Option(..., "--out", help="The ensemble model file to write (.npz)."),
) -> None:
    """Bundle Q-networks trained apart (other seeds) into one model file that decides on the mean of
    their Q-values: fewer lane changes where lanes are alike, where one network follows its error."""
    from stack.apps.folders import check_destination

    try:
        check_destination(out, "--out", "")
        from planner.learned import save_ensemble

        written = save_ensemble(models, out)
    except ValueError as error:
        fail(str(error))
    except OSError as error:
        fail(f"--out: cannot write {out} ({error.strerror})")
    Console().print(f"wrote {written}: the mean of {len(models)} Q-networks", highlight=False, soft_wrap=True)


def agents() -> None:
    """The decision agents `--agent` takes, one line each: the built-in ones, then those installed
    packages register (entry points `drivestack.agents`)."""
    from planner.factory import AGENT_DESCRIPTIONS

    _listing(AGENT_DESCRIPTIONS, AGENT_GROUP, 10)


def controllers() -> None:
    """The controllers `--controller` takes, one line each: the built-in ones, then those installed
    packages register (entry points `drivestack.controllers`)."""
    from common.plugins import CONTROLLER_GROUP
    from stack.apps.track import CONTROLLER_DESCRIPTIONS

    _listing(CONTROLLER_DESCRIPTIONS, CONTROLLER_GROUP, 13)


def _listing(descriptions: dict[str, str], group: str, width: int) -> None:
    """One line per built-in name, then per name installed in the entry-point `group`."""
    from common.plugins import entry_points

    for name, text in descriptions.items():
        typer.echo(f"{name:{width}} {text}")
    for name, target in entry_points(group).items():
        typer.echo(f"{name:{width}} installed plug-in {target}")
    typer.echo(f"{'':{width}} or a plug-in: {SPEC_FORMS} (docs/plugins.md)")


def view(
    path: Path = typer.Argument(..., help="A recording (.rrd) or a results folder made with --record."),
    worst: bool = typer.Option(
        False, "--worst", help="Open the folder's worst episode (collision, else slowest)."
    ),
    agent: str | None = typer.Option(None, help="With --worst on a comparison: whose worst episode."),
    web: bool = typer.Option(False, "--web", help="Serve rerun's web viewer on 127.0.0.1 instead."),
) -> None:
    """Open rerun's viewer on a recording, a results folder's recordings or its worst episode."""
    from stack.apps.options import rerun_or_fail

    rerun_or_fail("view")
    from stack.apps.view import display_problem, recordings_in, rerun_program, view

    try:
        recordings = recordings_in(path, worst, agent)
        rerun_program()
    except ValueError as error:
        fail(str(error))
    if problem := display_problem(web):
        fail(problem)
    code = view(recordings, web)
    if code:
        raise typer.Exit(code=code)


def gate_calibrate(
    out: Path = typer.Option(
        ..., "--out", help="The model file to write, the threshold in its metadata (.npz)."
    ),
    model: Path | None = typer.Option(
        None, "--model", help="An ensemble model file (default: the shipped ddqn)."
    ),
    config: Path = typer.Option(
        TRAIN_CONFIG,
        "--config",
        "-c",
        help="The training config whose world mix (train.scenarios) is in distribution.",
    ),
    episodes: int = typer.Option(10, "--episodes", min=1, max=10_000, help="Episodes per world of the mix."),
    seed: int = typer.Option(1005500, "--seed", min=0, help="Seed of each world's first episode."),
    percentile: float = typer.Option(
        98.5,
        "--percentile",
        min=50.0,
        max=99.99,
        help="The threshold's percentile of in-distribution disagreement.",
    ),
    measure: str = typer.Option(
        "advantage_ratio",
        "--measure",
        help="The disagreement: advantage_ratio (members' std of the choice's advantage over its "
        "mean) or std_q (members' std of Q(chosen)).",
    ),
) -> None:
    """Calibrate the uncertainty gate: the percentile of an ensemble's disagreement (`--measure`)
    over the worlds it trained on, written into a copy of its model file as
    `uncertainty_threshold` and `uncertainty_measure` (planner.uncertainty_threshold: null reads
    them)."""
    from planner.factory import SHIPPED_MODELS
    from planner.model_metadata import GATE_MEASURES
    from stack.apps.folders import check_destination
    from stack.apps.gate import calibrate, calibration_table, write_threshold
    from stack.settings.run import ConfigError, load_config

    source = model or SHIPPED_MODELS["ddqn"]
    try:
        check_destination(out, "--out", "")
        if measure not in GATE_MEASURES:
            fail(f"--measure: expected one of {', '.join(GATE_MEASURES)}, got {measure!r}")
        found = calibrate(load_config(config), source, episodes, seed, percentile, measure)
        written = write_threshold(source, out, found)
    except (ValueError, ConfigError) as error:
        fail(str(error))
    except OSError as error:
        fail(f"--out: cannot write {out} ({error.strerror})")
    console = Console()
    console.print(calibration_table(found), highlight=False, soft_wrap=True)
    console.print(
        f"wrote {written}: uncertainty_threshold {found.threshold:.4f} ({found.description()})",
        highlight=False,
        soft_wrap=True,
    )


def tracking(
    agents: str = typer.Option(
        "ddqn,mobil", help=f"Comma-separated names or a plug-in class: {SPEC_FORMS} (docs/plugins.md)."
    ),
    config: Path | None = typer.Option(
        None, "--config", "-c", help="YAML run config (default: configs/highway.yaml)."
    ),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    episodes: int | None = typer.Option(None, help="Seeded episodes per agent."),
    seed: int | None = typer.Option(None, help="Seed of the first episode."),
    scenario: str | None = typer.Option(None, help="Named world (drivestack scenarios)."),
    out: Path | None = typer.Option(None, help="Results folder (default: runs/tracking-<time>)."),
) -> None:
    """Tracking quality against the simulator's truth (precision, recall, RMSE, OSPA, phantom
    tracks), one world at a time (docs/perception.md)."""
    names = listed("--agents", agents)
    configs = per_agent(
        config, sets, [(name, None) for name in names], labels={"planner.agent": "--agents"},
        scenario=scenario, episodes=episodes, seed=seed,
    )  # fmt: skip
    plugins_or_fail(configs, ["--agents"] * len(configs))
    folder = claimed_for("tracking", out, agents, configs[0])
    from stack.apps.tracking import report

    until_interrupted(lambda: report(dict(zip(names, configs, strict=True)), folder))
