"""The `drivestack` commands that do not run episodes here: `sweep` (training runs on Ray Tune),
`export`, and the `agents` and `controllers` listings. Parsing and one-line errors only, like
`stack.apps.cli`, which registers them."""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from rich.console import Console

from records.plugins import AGENT_GROUP, SPEC_FORMS
from stack.apps.options import fail, ray_or_fail

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
    from stack.apps.training import check_memory
    from stack.core.config import ConfigError
    from stack.core.sweep_config import SWEEP_FILE, load_sweep, trial_config

    spec = resume / SWEEP_FILE if resume is not None else config or Path(SWEEP_FILE)
    if resume is not None and not spec.is_file():
        fail(f"--resume: {resume} is not a sweep folder (no {SWEEP_FILE})")
    try:
        sweep_file, base = load_sweep(spec)
    except ConfigError as error:
        fail(str(error))
    check_memory(trial_config(base, sweep_file.fixed, {}))
    ray_or_fail(ray or "local")
    from stack.apps.folders import claimed, location
    from stack.core.owner import Owner

    folder = claimed(location(resume or out, "sweep"), "sweep", Owner("sweep", ""), resume is not None, False)
    from stack.apps.sweep import sweep_and_report

    if sweep_and_report(sweep_file, base, folder, resume is not None, progress):
        sys.exit(130)


def export(
    model: Path = typer.Argument(..., help="A DDQN or DQN model file (.npz, from drivestack train)."),
    sb3: Path = typer.Option(..., "--sb3", help="The stable-baselines3 zip to write."),
) -> None:
    """Write a model file as a stable-baselines3 zip that `DQN.load` opens."""
    from stack.apps.folders import check_destination

    try:
        check_destination(sb3)
        from stack.apps.export import export_sb3

        written = export_sb3(model, sb3)
    except ValueError as error:
        fail(str(error))
    Console().print(f"wrote {written}: stable_baselines3.DQN.load({str(written)!r})", highlight=False)


def agents() -> None:
    """The decision agents `--agent` takes, one line each: the built-in ones, then those installed
    packages register (entry points `drivestack.agents`)."""
    from planner.factory import AGENT_DESCRIPTIONS

    _listing(AGENT_DESCRIPTIONS, AGENT_GROUP, 10)


def controllers() -> None:
    """The controllers `--controller` takes, one line each: the built-in ones, then those installed
    packages register (entry points `drivestack.controllers`)."""
    from records.plugins import CONTROLLER_GROUP
    from stack.apps.track import CONTROLLER_DESCRIPTIONS

    _listing(CONTROLLER_DESCRIPTIONS, CONTROLLER_GROUP, 13)


def _listing(descriptions: dict[str, str], group: str, width: int) -> None:
    """One line per built-in name, then per name installed in the entry-point `group`."""
    from records.plugins import entry_points

    for name, text in descriptions.items():
        typer.echo(f"{name:{width}} {text}")
    for name, target in entry_points(group).items():
        typer.echo(f"{name:{width}} installed plug-in {target}")
    typer.echo(f"{'':{width}} or a plug-in: {SPEC_FORMS} (docs/plugins.md)")
