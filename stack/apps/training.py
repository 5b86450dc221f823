"""The `drivestack train` command around `stack.training`: what it checks before any work (the
replay buffer fits in memory, the model it starts from fits the run, a run to resume is one), the
owner of its folder, and what it prints after; and the memory check of `--jobs` episode processes
that run, compare and safety make before any process starts."""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from planner.model_file import CHECKPOINT as CHECKPOINT_FILE
from stack.apps.options import AGAIN, cannot_write, configured, fail, ray_or_fail
from stack.runtime.machine import available_memory_bytes
from stack.runtime.owner import MARKER, Owner, fingerprint, owner_of

if TYPE_CHECKING:
    from stack.settings.run import RunConfig
    from stack.training.summary import TrainSummary

RESUME_ONLY_STEPS = "only --steps may change on resume (the run goes on as it was configured)"


def check_memory(config: RunConfig) -> None:
    """Refuse, before anything is allocated, a replay buffer (with the demonstrations) that does not
    fit in memory."""
    from stack.training.checks import memory_refusal

    if refusal := memory_refusal(config, available_memory_bytes()):
        fail(refusal)


def check_batched(config: RunConfig) -> None:
    """Refuse, before the run folder exists, `train.worlds` for a loop the batch does not run
    (MPC, the dynamic plant, a sensor model, random traffic) in any world of the training mix, or a
    grid feature it does not encode."""
    if config.train.worlds is None:
        return
    from perception.grid import BATCHED_FEATURES
    from stack.batch.closed_loop_batch import refusal
    from stack.settings.run import training_worlds

    reason: str | None
    if unbatched := [name for name in config.perception.features if name not in BATCHED_FEATURES]:
        computed = ", ".join(BATCHED_FEATURES)
        reason = f"the batched grid computes {computed}, not perception.features {unbatched[0]}"
    else:
        worlds = training_worlds(config)
        reason = next((f"{name}: {why}" for name, world in worlds.items() if (why := refusal(world))), None)
    if reason:
        fail(f"train.worlds: {reason}; train.envs steps such worlds one at a time")


WORKER_BYTES = 450 * 2**20
"""Memory one episode process takes at most [bytes] (240-440 MB measured: simulator, torch)."""


def check_jobs(jobs: int) -> None:
    """Refuse, before any process starts, more episode processes (`--jobs`, at most one per usable
    CPU) than the available memory holds."""
    from stack.runtime.executors import usable_cpus

    workers = min(jobs, usable_cpus())
    if workers > 1 and (available := available_memory_bytes()) is not None:
        if workers * WORKER_BYTES > 0.8 * available:
            fail(
                f"--jobs: {workers} processes need about {workers * WORKER_BYTES / 2**30:.1f} GB; "
                f"{available / 2**30:.1f} GB of memory is available"
            )


def check_envs(config: RunConfig) -> None:
    """Refuse, before any process starts, more env processes (`train.envs`, one CPU each) than this
    machine has usable CPUs, or than its available memory holds (as `--jobs` and a sweep are)."""
    from stack.runtime.machine import usable_cpus

    envs, cpus = config.train.envs, usable_cpus()
    if envs > 1 and envs > cpus:
        fail(
            f"train.envs: {envs} processes step one CPU each, but this machine has {cpus}; use at most {cpus}"
        )
    if (
        envs > 1
        and (available := available_memory_bytes()) is not None
        and envs * WORKER_BYTES > 0.8 * available
    ):
        fail(
            f"train.envs: {envs} processes need about {envs * WORKER_BYTES / 2**30:.1f} GB; "
            f"{available / 2**30:.1f} GB of memory is available"
        )


def check_ray_shards(config: RunConfig, address: str | None) -> None:
    """With `--ray`, refuse in one line, before the run folder exists: per-world envs (only batched
    worlds are sharded over actors), no Ray or no cluster at `address`, and a cluster with fewer
    CPUs than the shards take (one each: the actors would wait for them forever)."""
    if address is None:
        return
    if config.train.worlds is None:
        fail("--ray: steps the shards of batched worlds as Ray actors; give --worlds N (train.worlds) too")
    ray_or_fail(address)
    if address == "local":
        return
    import ray

    envs, cpus = config.train.envs, ray.cluster_resources().get("CPU", 0)
    if envs > cpus:
        fail(
            f"--ray {address}: {envs} world shards (train.envs) take one CPU each, but the cluster has "
            f"{cpus:g}; use --envs {int(cpus)} or fewer, or add nodes"
        )


def check_init_model(config: RunConfig) -> None:
    """Refuse, before the run folder exists and before torch is imported, a `train.init_model`
    that does not fit the run, or a learned expert's model that does not fit the roads it teaches on."""
    from planner.model_file import ModelFileError
    from stack.runs.model_fit import checked_expert_model, checked_start_model

    try:
        checked_start_model(config)
        checked_expert_model(config)
    except ModelFileError as error:
        fail(str(error))


def train_or_fail(config: RunConfig, folder: Path, progress: bool, ray: str | None = None) -> bool:
    """`drivestack train` in `folder` (with `ray`, an address, the world shards as Ray actors
    there); a checkpoint that cannot be resumed is a one-line error. True when interrupted
    (resumable)."""
    from planner.model_file import CHECKPOINT, ModelFileError, load_checkpoint
    from stack.training.checks import checkpoint_bytes

    try:
        if (checkpoint := folder / CHECKPOINT).is_file():
            load_checkpoint(checkpoint, arrays=False, max_bytes=checkpoint_bytes(config))
        return train_and_report(config, folder, progress, ray)
    except ModelFileError as error:
        fail(str(error))


def train_and_report(config: RunConfig, folder: Path, progress: bool, ray: str | None = None) -> bool:
    """Train (or resume) in `folder` and print the outcome; True when a signal stopped it (its
    checkpoint written: resumable). A signal while the env processes start stops before training;
    signals after training only wait for the files. A dead env process or Ray actor (as it starts
    or later) ends it in one line, exit code 1."""
    from stack.runtime.files import write_failure
    from stack.runtime.interrupts import deferred, received
    from stack.training.envs import EnvWorkerDied, worker_death
    from stack.training.trainer import Trainer
    from stack.training.world_shards import ShardDied

    try:
        with deferred():
            trainer = Trainer(config, folder, progress=progress, ray=ray)
    except KeyboardInterrupt:
        print("interrupted before training started; nothing trained", file=sys.stderr)
        return True
    except ShardDied as error:
        print(f"error: {worker_death(None, folder, error)}", file=sys.stderr)
        sys.exit(1)
    with deferred(interrupt_after=False):
        try:
            summary = trainer.run()
        except EnvWorkerDied as error:
            print(f"error: {error}", file=sys.stderr)
            sys.exit(1)
        except OSError as error:
            if not write_failure(error):
                raise
            fail(f"{cannot_write(error)}; {training_kept(folder, config)}")
        report(summary, folder)
    return summary.interrupted or received()


def training_kept(folder: Path, config: RunConfig) -> str:
    """What a training run in `folder` kept when a file could not be written, and how to go on."""
    if not (folder / "config.yaml").is_file():
        return AGAIN
    resume = f"free space, then `drivestack train --resume {folder}`"
    steps = checkpoint_steps(folder, failing=False)
    if steps is None:
        return f"no checkpoint was written yet: {resume} starts it again"
    if steps >= config.train.steps:
        return f"its {steps} steps are trained and checkpointed: {resume} writes the files still missing"
    return f"its last checkpoint (step {steps}) is kept: {resume} goes on from it"


def report(summary: TrainSummary, folder: Path) -> None:
    """The outcome of a training run on the terminal."""
    best = summary.best_validation
    found = (
        "no validation yet"
        if best is None
        else (
            f"best validation at step {best.step}: collision rate {best.collision_rate:.1%}, "
            f"mean return {best.mean_return:.2f}, mean speed {best.mean_speed:.2f} m/s"
        )
    )
    print(f"{summary.algorithm}: {summary.steps} steps in {summary.wall_time_s:.0f} s; {found}")
    resumable = " (interrupted: resume with --resume)" if summary.interrupted else ""
    print(f"run folder: {folder}{resumable}")


def training_owner(config: RunConfig) -> Owner:
    """The owner a training run records in its folder: the hash of its config without
    `train.steps`, the one key a resumed run may change (grow), and the `unfingerprinted` ones."""
    from stack.settings.history import unfingerprinted

    data = config.model_dump(mode="json", exclude=unfingerprinted(config))
    data["train"].pop("steps")
    return Owner("train", fingerprint(json.dumps(data, sort_keys=True)))


def resumed_training(
    folder: Path, sets: list[str], steps: int | None, given: Mapping[str, object], adopt: bool = False
) -> RunConfig:
    """The config `train --resume folder` goes on with: the run's own, `--steps` grown; a one-line
    error (exit 2) for an option that would have no effect (`given`, by option name), a `--set`
    that changes anything, fewer steps, a folder that is not an interrupted training run, and a
    folder without an owner record unless `adopt` (`stack.apps.adoption`)."""
    if unused := next((option for option, value in given.items() if value is not None), None):
        fail(f"{unused}: has no effect with --resume; {RESUME_ONLY_STEPS}")
    found = owner_of(folder)
    if found is not None and found.command != "train":
        fail(f"--resume: {folder} holds the results of `{found.command}`, not a training run")
    if not (folder / "config.yaml").is_file() or (found is None and not (folder / CHECKPOINT_FILE).is_file()):
        fail(f"--resume: {folder} is not a training run folder (no config.yaml and checkpoint.npz)")
    if found is None and not adopt:
        fail(
            f"--resume: {folder} records no owner (made before {MARKER} existed); if its config.yaml is "
            "the one it was trained with, add --adopt: it is checked against the run's files, then the "
            "run goes on"
        )
    if found is not None and adopt:
        fail(f"--adopt: {folder} already records its owner; resume without --adopt")
    from stack.settings.checks import first_change

    stored = configured(folder / "config.yaml", [])
    config = configured(folder / "config.yaml", sets, train__steps=steps)
    old, new = stored.model_dump(mode="json"), config.model_dump(mode="json")
    old["train"].pop("steps"), new["train"].pop("steps")
    if changed := first_change(old, new):
        key, was, asked = changed
        fail(f"--set {key}: the run in {folder} was trained with {was!r}, not {asked!r}; {RESUME_ONLY_STEPS}")
    if config.train.steps < stored.train.steps:
        fail(f"--steps: expected at least {stored.train.steps} (the run's budget); {RESUME_ONLY_STEPS}")
    if adopt:
        from stack.apps.adoption import adoption_refusal

        if why := adoption_refusal(folder, stored):
            fail(why)
    if (
        (done := checkpoint_steps(folder)) is not None
        and done >= config.train.steps
        and finished(folder, done)
    ):
        fail(
            f"--resume: {folder} finished its {done} steps; nothing to resume "
            f"(--steps above {done} trains it further)"
        )
    return config


def finished(folder: Path, steps: int) -> bool:
    """Whether `folder`'s summary.json is that of a run finished at `steps` (a run whose last files
    could not be written, a full disk, lacks it: `--resume` writes them, training nothing)."""
    from stack.training.summary import TrainSummary

    try:
        summary = TrainSummary.from_json(json.loads((folder / "summary.json").read_bytes()))
        return summary.steps >= steps and summary.interrupted is False
    except (OSError, ValueError, KeyError, TypeError):
        return False


def checkpoint_steps(folder: Path, failing: bool = True) -> int | None:
    """The steps the checkpoint in `folder` holds (None without one); a one-line error for a
    file that is not a checkpoint (None instead, without `failing`)."""
    from planner.model_file import ModelFileError, load_checkpoint
    from stack.training.checkpoint import checkpoint_steps as steps_done

    if not (folder / CHECKPOINT_FILE).is_file():
        return None
    try:
        _, metadata = load_checkpoint(folder / CHECKPOINT_FILE, arrays=False)
        return steps_done(metadata)
    except ModelFileError as error:
        if failing:
            fail(str(error))
    except (KeyError, TypeError, ValueError):
        if failing:
            fail(f"{folder / CHECKPOINT_FILE}: not a training checkpoint (no step count)")
    return None
