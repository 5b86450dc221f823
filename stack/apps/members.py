"""`drivestack train` of an ensemble config (`train.members` > 1): its runs trained one after the
other in the folder's `seed-S` folders, then one model file of them (`planner.learned.save_ensemble`),
so one command and the folder's config.yaml make the shipped three-seed model."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from stack.apps.options import fail

if TYPE_CHECKING:
    from planner.ddqn import Demonstrations
    from stack.settings.run import RunConfig

SUMMARY = "summary.json"


def member_configs(config: RunConfig) -> dict[str, RunConfig]:
    """Each run of an ensemble config by its folder's name `seed-S`: the config with seed S (its
    `seed` and the next members - 1) and one member."""
    one = config.train.model_copy(update={"members": 1, "member_jobs": 1})
    seeds = range(config.seed, config.seed + config.train.members)
    return {f"seed-{seed}": config.model_copy(update={"seed": seed, "train": one}) for seed in seeds}


def check_unfinished(folder: Path, config: RunConfig) -> None:
    """Refuse `--resume` of an ensemble written after every member finished `train.steps`."""
    from stack.apps.training import finished

    members = member_configs(config)
    if all(finished(folder / name, member.train.steps) for name, member in members.items()) and (
        (folder / SUMMARY).is_file()
    ):
        fail(
            f"--resume: {folder} finished its {config.train.members} members' {config.train.steps} steps; "
            f"nothing to resume (--steps above {config.train.steps} trains them further)"
        )


def train_members(config: RunConfig, folder: Path, progress: bool, ray: str | None = None) -> bool:
    """Train (or resume) each member in `folder/seed-S`, a finished one kept as it is, then write
    the ensemble of their best.npz and of their final.npz as `folder`'s and its summary.json. True
    when a signal stopped a member (its checkpoint written: `--resume folder` goes on)."""
    from stack.settings.run import write_config
    from stack.training.demonstrations import recorded_once

    write_config(config, folder / "config.yaml", "the resolved config; --resume reads it")
    members = member_configs(config)
    with recorded_once():
        if min(config.train.member_jobs, len(unfinished(members, folder))) > 1:
            stopped = _train_together(members, folder, config.train.member_jobs, progress, ray)
        else:
            stopped = _train_each(members, folder, progress, ray)
    if stopped:
        print(f"the ensemble goes on with `drivestack train --resume {folder}`", file=sys.stderr)
        return True
    write_ensemble(folder, list(members))
    return False


def unfinished(members: dict[str, RunConfig], folder: Path) -> list[str]:
    """The members (by folder name) that have not trained all their steps in `folder`."""
    from stack.apps.training import finished

    return [name for name, member in members.items() if not finished(folder / name, member.train.steps)]


def _train_each(members: dict[str, RunConfig], folder: Path, progress: bool, ray: str | None) -> bool:
    """Train (or resume) each member in `folder/seed-S` in turn; True when a signal stopped one."""
    missing = unfinished(members, folder)
    for number, (name, member) in enumerate(members.items(), 1):
        which = f"member {number} of {len(members)} (seed {member.seed})"
        if name not in missing:
            print(f"{which}: finished in {folder / name}", file=sys.stderr)
            continue
        print(f"{which} in {folder / name}", file=sys.stderr)
        if _train_member(member, folder / name, progress, ray):
            return True
    return False


def _train_member(member: RunConfig, run: Path, progress: bool, ray: str | None) -> bool:
    """Train (or resume) one member in its folder `run`, claimed for it; True when stopped."""
    from stack.apps.training import train_or_fail, training_owner
    from stack.runtime.owner import FolderRefused, claim

    try:
        lock = claim(run, training_owner(member), resuming=run.is_dir(), restart=False)
    except FolderRefused as error:
        fail(str(error))
    with lock:
        return train_or_fail(member, run, progress, ray)


STOPPED = 130
"""A member process's exit code when a signal stopped it with its checkpoint."""


def _member_process(
    member: RunConfig, run: Path, ray: str | None, shared: dict[str, Demonstrations] | None
) -> None:
    """A member trained in a process of its own (no progress bar: several run at once), with the
    demonstrations the ensemble recorded (`shared`); exits 0 when it finished, `STOPPED` when a
    signal stopped it, else with its one-line error's code."""
    from stack.runtime.interrupts import catch_signals

    catch_signals()
    import typer

    from stack.training import demonstrations

    demonstrations.adopt_shared(shared)
    try:
        stopped = _train_member(member, run, False, ray)
    except typer.Exit as error:
        sys.exit(error.exit_code)
    except KeyboardInterrupt:
        print(f"{run}: interrupted before training started; nothing trained", file=sys.stderr)
        stopped = True
    sys.exit(STOPPED if stopped else 0)


def _train_together(
    members: dict[str, RunConfig], folder: Path, jobs: int, progress: bool, ray: str | None
) -> bool:
    """Train (or resume) the unfinished members `jobs` at a time, each in a spawned process, after
    recording the demonstrations once here (a member resumed from its checkpoint has its own).
    True when a signal stopped them (each writes its checkpoint; a signal here is passed on to
    them, and one that ends a member still starting is a stop too); a member that failed (its one
    line printed) ends the command with its exit code once the others are done."""
    import multiprocessing
    import os
    import signal

    import typer

    from planner.model_file import CHECKPOINT
    from stack.runtime.interrupts import handled_by, note_stop
    from stack.training import demonstrations

    missing = unfinished(members, folder)
    fresh = [name for name in missing if not (folder / name / CHECKPOINT).is_file()]
    if fresh and members[fresh[0]].train.demonstrations is not None:
        try:
            demonstrations.shared_demonstrations(members[fresh[0]], progress)
        except KeyboardInterrupt:
            print("interrupted while the demonstrations were recorded; nothing trained", file=sys.stderr)
            return True
    context = multiprocessing.get_context("spawn")
    waiting = list(missing)
    running: dict[str, Any] = {}
    codes: dict[str, int] = {}
    stop = False

    def passed_on(signum: int, frame: object) -> None:
        nonlocal stop
        stop = True
        note_stop()
        for process in running.values():
            if process.is_alive() and process.pid is not None:
                os.kill(process.pid, signal.SIGTERM)

    with handled_by(passed_on):
        while waiting or running:
            while waiting and len(running) < jobs and not stop:
                name = waiting.pop(0)
                print(f"member seed {members[name].seed} in {folder / name}", file=sys.stderr)
                shared = demonstrations.shared_now()
                process = context.Process(
                    target=_member_process, args=(members[name], folder / name, ray, shared)
                )
                process.start()
                running[name] = process
            for name, process in list(running.items()):
                process.join(timeout=0.5)
                if process.exitcode is not None:
                    codes[name] = process.exitcode
                    del running[name]
            if stop:
                waiting.clear()
    failed = [code for code in codes.values() if code not in (0, STOPPED) and not (stop and code < 0)]
    if failed:
        raise typer.Exit(code=failed[0] if failed[0] > 0 else 1)
    return stop or STOPPED in codes.values()


def write_ensemble(folder: Path, names: list[str]) -> None:
    """`folder`'s best.npz and final.npz, each the ensemble of its members' (best.npz only when
    every member kept one), and summary.json: each member's seed, steps, time and best validation."""
    from stack.apps.options import cannot_write
    from stack.runtime.files import write_json
    from stack.training.trainer import BEST, FINAL

    summaries = [json.loads((folder / name / SUMMARY).read_bytes()) for name in names]
    try:
        written = {kind: ensemble_of(folder, names, kind) for kind in (BEST, FINAL)}
        write_json(
            folder / SUMMARY,
            {
                "algorithm": summaries[0]["algorithm"],
                "network": summaries[0]["network"],
                "members": [
                    {"folder": name, "seed": int(name.removeprefix("seed-"))}
                    | {key: summary[key] for key in ("steps", "wall_time_s", "best_validation")}
                    for name, summary in zip(names, summaries, strict=True)
                ],
                "wall_time_s": sum(summary["wall_time_s"] for summary in summaries),
                "best_model": written[BEST],
                "final_model": written[FINAL],
            },
        )
    except OSError as error:
        fail(f"{cannot_write(error)}; the members are trained: free space, then `train --resume {folder}`")
    minutes = sum(summary["wall_time_s"] for summary in summaries) / 60
    kept = ", ".join(path for path in written.values() if path)
    print(f"ensemble of {len(names)} members ({minutes:.0f} min of training, the members' added up): {kept}")


def ensemble_of(folder: Path, names: list[str], kind: str) -> str | None:
    """The ensemble of the members' `kind` file written as `folder / kind` (None when a member
    has none: a run whose validation never ran keeps no best.npz); a one-line error for a member
    file that does not fit."""
    from planner.learned import save_ensemble
    from planner.model_file import ModelFileError

    if not all((folder / name / kind).is_file() for name in names):
        return None
    try:
        return str(save_ensemble([folder / name / kind for name in names], folder / kind))
    except ModelFileError as error:
        fail(str(error))
