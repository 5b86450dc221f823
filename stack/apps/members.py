"""`drivestack train` of an ensemble config (`train.members` > 1): its runs trained one after the
other in the folder's `seed-S` folders, then one model file of them (`planner.learned.save_ensemble`),
so one command and the folder's config.yaml make the shipped three-seed model."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from stack.apps.options import fail

if TYPE_CHECKING:
    from stack.settings.run import RunConfig

SUMMARY = "summary.json"


def member_configs(config: RunConfig) -> dict[str, RunConfig]:
    """Each run of an ensemble config by its folder's name `seed-S`: the config with seed S (its
    `seed` and the next members - 1) and one member."""
    one = config.train.model_copy(update={"members": 1})
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
        stopped = _train_each(members, folder, progress, ray)
    if stopped:
        print(f"the ensemble goes on with `drivestack train --resume {folder}`", file=sys.stderr)
        return True
    write_ensemble(folder, list(members))
    return False


def _train_each(members: dict[str, RunConfig], folder: Path, progress: bool, ray: str | None) -> bool:
    """Train (or resume) each member in `folder/seed-S` in turn; True when a signal stopped one."""
    from stack.apps.training import finished, train_or_fail, training_owner
    from stack.runtime.owner import FolderRefused, claim

    for number, (name, member) in enumerate(members.items(), 1):
        run, which = folder / name, f"member {number} of {len(members)} (seed {member.seed})"
        if finished(run, member.train.steps):
            print(f"{which}: finished in {run}", file=sys.stderr)
            continue
        print(f"{which} in {run}", file=sys.stderr)
        try:
            lock = claim(run, training_owner(member), resuming=run.is_dir(), restart=False)
        except FolderRefused as error:
            fail(str(error))
        with lock:
            if train_or_fail(member, run, progress, ray):
                return True
    return False


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
    print(f"ensemble of {len(names)} members ({minutes:.0f} min of training): {kept}")


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
