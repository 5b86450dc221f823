"""What every `drivestack` sub-command shares: the packaged default configs, `--set` overrides, the
one-line error (exit 2), and checks done before any work."""

from __future__ import annotations

import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import typer
import yaml
from rich.console import Console
from rich.markup import escape

from stack.runtime.interrupts import catch_signals, ignore_signals, received

if TYPE_CHECKING:
    from stack.settings.run import RunConfig


CONFIGS = Path(__file__).resolve().parents[1] / "configs"
"""The default configs, shipped in the package (the checkout's configs/ links to them)."""
RUN_CONFIG, TRAIN_CONFIG = CONFIGS / "highway.yaml", CONFIGS / "train" / "ddqn.yaml"
PLANT_HELP = "The ego's vehicle model: kinematic | dynamic (sim.plant)."
VARIANT_HELP = (
    "DeepCars rules: paper (the paper's text: 9-row line of sight, epsilon 0.2) | public (the "
    "authors' code: 4-row line of sight, epsilon 1.0 x0.995 per step, floor 0.01) | all (both)."
)
TRAFFIC_HELP = (
    "The traffic's drivers (highway.traffic.drivers): highway-env | calibrated | aggressive | "
    "cautious | distracted | blind | mixed | random, or shares: calibrated=0.7,aggressive=0.3 "
    "(docs/traffic.md)."
)
SET_HELP = "KEY=VALUE: a dotted config key and a YAML value (repeatable); overrides the config file."
RAY_HELP = (
    "Run the episodes as Ray tasks: on a local instance started for the run (bare --ray), on the "
    "cluster `ray start` made (auto) or at HOST:PORT; needs pip install 'drivestack\\[ray]'."
)
TRAIN_RAY_HELP = (
    "Step the batched worlds' shards (train.envs of train.worlds / envs worlds) as Ray actors, the "
    "learner here: on a local instance (bare --ray), the cluster `ray start` made (auto) or at "
    "HOST:PORT; the same model as --envs (docs/ray.md); needs pip install 'drivestack\\[ray]'."
)
JOBS_OPTION = typer.Option(
    1, min=1, help="Parallel processes for the episodes (at most one per CPU; checked against memory)."
)
SET_KEY = re.compile(r"[A-Za-z_][\w-]*(\.[A-Za-z_][\w-]*)*")
OPTIONS = {
    "planner__agent": "--agent",
    "planner__model": "--model",
    "controller__type": "--controller",
    "controller__lane_change_duration_s": "--duration",
    "sim__backend": "--backend",
    "sim__plant": "--plant",
    "train__algorithm": "--agent",
    "train__steps": "--steps",
    "train__envs": "--envs",
    "train__worlds": "--worlds",
}
"""The CLI option behind each override (the others are named as their key: --seed, --scenario)."""
MAX_SET_LENGTH = 1000
"""Longest --set value [characters]."""


def fail(message: str) -> NoReturn:
    """`message` as one line on stderr (brackets in it printed as they are), then exit code 2."""
    Console(stderr=True, emoji=False).print(
        f"[red]error:[/red] {escape(message)}", highlight=False, soft_wrap=True
    )
    raise typer.Exit(code=2)


def configured(
    path: Path | None, sets: list[str], labels: dict[str, str] | None = None, **overrides: object
) -> RunConfig:
    """The validated config at `path` (the packaged run config when None) with the `--set` entries
    and then the CLI `overrides` applied, or a one-line error (exit 2); `labels` (dotted key ->
    option) name the option to blame where it is not the usual one."""
    given = {key: value for key, value in overrides.items() if value is not None}
    set_values = parsed_sets(sets)
    values = {**set_values, **given}
    blamed = {key.replace("__", "."): f"--set {key.replace('__', '.')}" for key in set_values}
    blamed |= {key.replace("__", "."): OPTIONS.get(key, f"--{key.replace('__', '.')}") for key in given}
    blamed |= {key: label for key, label in (labels or {}).items() if key in blamed}
    from stack.settings.run import ConfigError, load_config

    try:
        return load_config(path or RUN_CONFIG, blamed, **values)
    except ConfigError as error:
        fail(str(error))


def per_agent(
    path: Path | None,
    sets: list[str],
    agents: Sequence[tuple[str | None, Path | str | None]],
    labels: dict[str, str] | None = None,
    model_option: str = "--model",
    **overrides: object,
) -> list[RunConfig]:
    """One `configured` config per (agent name, model file) pair; None keeps the config's own. A
    model file given (by `model_option`) for an agent that loads none is refused: it would have
    no effect."""
    from records import LEARNED_AGENTS

    configs = []
    for name, model in agents:
        config = configured(path, sets, labels, planner__agent=name, planner__model=model, **overrides)
        if model is not None and config.planner.agent not in LEARNED_AGENTS:
            fail(
                f"{model_option}: the {config.planner.agent} agent loads no model file "
                f"(only {', '.join(LEARNED_AGENTS)} do)"
            )
        configs.append(config)
    return configs


def parsed_sets(sets: list[str]) -> dict[str, object]:
    """`--set` entries as config overrides (dotted keys as `a__b`); YAML values without anchors or
    aliases, so a short value cannot expand into a huge one. `null` (or `~`) sets the key to null
    (`NULL`: validation says where null is not allowed); an empty value is refused."""
    from stack.runtime.yaml_text import strict_yaml
    from stack.settings.run import NULL

    values: dict[str, object] = {}
    for entry in sets:
        key, separator, raw = entry.partition("=")
        if not separator or not SET_KEY.fullmatch(key):
            fail(f"--set: expected KEY=VALUE with a dotted key (e.g. seed=3), got {entry[:80]!r}")
        if not raw.strip():
            fail(f"--set {key}: expected a value after '=' (null sets the key to null)")
        if len(raw) > MAX_SET_LENGTH:
            fail(f"--set {key}: expected a YAML value of at most {MAX_SET_LENGTH} characters, got {len(raw)}")
        try:
            value = strict_yaml(raw)
        except yaml.YAMLError as error:
            problem = getattr(error, "problem", None)
            reason = f" ({str(problem)[:80]})" if problem else ""
            fail(f"--set {key}: not a YAML value{reason}: {raw[:80]!r}")
        values[key.replace(".", "__")] = NULL if value is None else value
    return values


def ray_or_fail(address: str | None) -> None:
    """With `--ray`, connect now (see `stack.runtime.ray_tasks.connect`), so a missing Ray or an
    unreachable address is one line before any work."""
    if address is None:
        return
    from stack.runtime.ray_tasks import RayUnavailable, connect

    try:
        connect(address)
    except RayUnavailable as error:
        fail(str(error))


def rerun_or_fail(option: str, wanted: bool = True) -> None:
    """With `wanted` (`--record`, `view`), refuse in one line, before any work, when rerun is not
    installed (it is the optional extra `viz`)."""
    import importlib.util

    if wanted and importlib.util.find_spec("rerun") is None:
        fail(f"{option}: needs rerun (rerun-sdk), which is not installed: pip install 'drivestack[viz]'")


def bare_ray_as_local(arguments: list[str]) -> list[str]:
    """`--ray` without an address (last, or followed by another option) as `--ray local`."""
    return [
        "--ray=local"
        if word == "--ray" and (index + 1 == len(arguments) or arguments[index + 1][:1] == "-")
        else word
        for index, word in enumerate(arguments)
    ]


def listed(option: str, value: str) -> list[str]:
    """The comma-separated names of `value`, or a one-line error for an empty list or entry."""
    names = [name.strip() for name in value.split(",")]
    if not all(names):
        fail(f"{option}: expected comma-separated names, none of them empty, got {value!r}")
    return names


def population_option(value: str | None) -> str | dict[str, float] | None:
    """`--traffic`'s value: a population's name, or NAME=SHARE,... as shares (checked by the
    config's validation); a one-line error for a share that is not a number."""
    if value is None or "=" not in value:
        return value
    shares: dict[str, float] = {}
    for entry in listed("--traffic", value):
        name, _, share = entry.partition("=")
        try:
            shares[name.strip()] = float(share)
        except ValueError:
            fail(f"--traffic: expected NAME=SHARE with a number for the share, got {entry!r}")
    return shares


def populations_option(value: str | None) -> list[str | dict[str, float] | None]:
    """`benchmark --traffic`'s value: several population names (A,B,...: a traffic axis), each
    once, or one population as `population_option` reads it."""
    if value is None or "=" in value or "," not in value:
        return [population_option(value)]
    names = listed("--traffic", value)
    if len(set(names)) < len(names):
        fail(f"--traffic: expected each population once, got {value!r}")
    return list(names)


def chosen(option: str, value: str, options: tuple[str, ...]) -> tuple[str, ...]:
    """The comma-separated names of `value` (`all`: every option), or a one-line error."""
    names = options if value == "all" else tuple(listed(option, value))
    if unknown := [name for name in names if name not in options]:
        fail(f"{option}: unknown {unknown[0]!r}; available: {', '.join(options)}, all")
    return names


def _print_version(value: bool) -> None:
    """`--version`: the installed distribution's version, then exit."""
    if value:
        from importlib.metadata import version

        typer.echo(f"drivestack {version('drivestack')}")
        raise typer.Exit()


AGAIN = "free space (or make the folder writable) and run the command again"
"""What to do after a write failure when nothing that finished was kept."""


WORKER_PLUGIN = "a worker could not load a plug-in that loaded here (docs/plugins.md, Processes and Ray)"
"""Said before the plug-in's own error when it fails in a `--jobs` process or on a Ray worker: the
command checked every plug-in before any work, so only the worker's machine or environment differs."""


def until_interrupted(work: Callable[[], bool], kept: Callable[[], str] = lambda: AGAIN) -> None:
    """Run `work`, which returns True when Ctrl-C cut it short with its finished part written, and
    exit 130 then; one line (and exit 130) when it was cut before anything finished. A results
    file that cannot be written (a full disk, a read-only folder) is one line (exit 2) saying
    what was kept and how to go on (`kept`); so is a plug-in that a worker could not load."""
    from common.plugins import PluginError
    from stack.runtime.files import write_failure

    try:
        interrupted = work()
    except KeyboardInterrupt:
        print("interrupted before anything finished; nothing written", file=sys.stderr)
        sys.exit(130)
    except OSError as error:
        if not write_failure(error):
            raise
        fail(f"{cannot_write(error)}; {kept()}")
    except PluginError as error:
        fail(f"{WORKER_PLUGIN}: {error}")
    if interrupted:
        sys.exit(130)


def cannot_write(error: OSError) -> str:
    """`cannot write FILE (why)` for a write failure."""
    where = f" {error.filename}" if error.filename else ""
    return f"cannot write{where} ({error.strerror or error})"


def guarded(app: typer.Typer, arguments: list[str] | None = None) -> None:
    """Run the CLI `app`; a file that cannot be written (a full disk, a read-only folder) is one
    line (exit 2), a failure nobody foresaw one line pointing at `--debug` (which shows the
    traceback) instead of a traceback."""
    arguments = bare_ray_as_local(list(sys.argv[1:] if arguments is None else arguments))
    debug = "--debug" in arguments
    if debug:
        arguments.remove("--debug")
    if catch_signals():
        sys.exit(130)
    try:
        app(arguments, prog_name="drivestack")
    except SystemExit as done:
        ignore_signals()
        if received() and not done.code:
            sys.exit(130)
        raise
    except Exception as error:  # noqa: BLE001 - the last line of defence, deliberately broad
        from common.plugins import PluginFailed
        from stack.runtime.files import write_failure
        from stack.settings.run import printable

        ignore_signals()
        if debug:
            raise
        if isinstance(error, PluginFailed):
            print(f"error: {printable(str(error))}", file=sys.stderr)
            sys.exit(1)
        if write_failure(error):
            print(f"error: {cannot_write(error)}", file=sys.stderr)
            sys.exit(2)
        message = str(error).splitlines()[0][:200] if str(error) else ""
        print(
            f"internal error: {type(error).__name__}: {message} (run with --debug for the traceback)",
            file=sys.stderr,
        )
        sys.exit(1)


RAY_OPTION = typer.Option(None, "--ray", metavar="[ADDRESS]", help=RAY_HELP)
RECORD_HELP = (
    "Write a rerun recording (.rrd) per {item} into OUT/recordings (docs/recording.md; open it with "
    "drivestack view); needs pip install 'drivestack\\[viz]'."
)
VERSION_OPTION = typer.Option(
    False, "--version", callback=_print_version, is_eager=True, help="Print the version and exit."
)
