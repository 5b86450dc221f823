"""`drivestack sweep`: `drivestack train` runs over a grid or random space (`stack.settings.sweep`)
as Ray Tune trials. Each trial trains in its own run folder, `trials/<trial id>` (the same
checkpoints, best model and summary as `drivestack train`), and reports every long real-time
validation to Tune: `score` is the sweep's metric of the trial's kept (best) model so far. An
interrupted sweep continues with `--resume`: Tune restarts the unfinished trials and each picks up
its run folder's last checkpoint.

The sweep folder: config.yaml (the base config, fixed overrides applied), sweep.yaml (the sweep
file, pointing at config.yaml, which `--resume` reads), tune/ (Tune's state), trials/, and the
report of `stack.apps.sweep_report`.
"""

from __future__ import annotations

import logging
import math
import os
import signal
from pathlib import Path
from typing import Any

import yaml

from planner.scores import Validation
from stack.apps.sweep_report import TRIALS, report
from stack.runtime.files import write_text
from stack.runtime.interrupts import deferred, received, stopped_by
from stack.runtime.owner import Owner, claim, fingerprint
from stack.settings.run import write_config
from stack.settings.sweep import SWEEP_FILE, SweepFile, trial_config

BASE, TUNE = "config.yaml", "tune"
SCORE = "score"
"""The metric every trial reports: the sweep's metric of its kept model (NaN before one is kept)."""


def prepare(sweep: SweepFile, base: Path, folder: Path) -> None:
    """A new sweep folder: the base config with the fixed overrides as config.yaml, and the sweep
    file pointing at it as sweep.yaml. The file keeps the fixed overrides too: every trial applies
    them again over its params, since a `scenario` param moves the base to another world."""
    write_config(trial_config(base, sweep.fixed, {}), folder / BASE, "the base config of every trial")
    spec = sweep.model_dump(mode="json") | {"config": BASE}
    write_text(folder / SWEEP_FILE, yaml.safe_dump(spec, sort_keys=False))


def tune_space(sweep: SweepFile) -> dict[str, Any]:
    """The sweep's space as Tune's param_space: lists as grid searches, the rest as distributions."""
    from ray import tune

    ranges = {"uniform": tune.uniform, "loguniform": tune.loguniform, "randint": tune.randint}
    space: dict[str, Any] = {}
    for key, values in sweep.space.items():
        if isinstance(values, list):
            space[key] = tune.grid_search(values)
        else:
            ((kind, bounds),) = values.items()
            space[key] = tune.choice(bounds) if kind == "choice" else ranges[kind](*bounds)
    return space


TRIAL = "sweep trial"
"""The owner a trial's run folder records: `train --resume` refuses it, the sweep resumes it."""


def train_trial(params: dict[str, Any], folder: Path, metric: str, fixed: dict[str, Any]) -> None:
    """One Tune trial: a training run in folder/trials/<trial id> with `params` and the sweep's
    `fixed` overrides over the sweep's base config, resumed from that folder's checkpoint when an
    earlier attempt left one. The trial owns and locks its folder while it trains
    (`stack.runtime.owner`)."""
    from ray import tune

    from stack.training.trainer import Trainer

    out = folder / TRIALS / tune.get_context().get_trial_id()
    kept = math.nan

    def heard(validation: Validation) -> None:
        nonlocal kept
        if validation.period == "long":
            kept = getattr(validation, metric) if validation.improved else kept
            tune.report({"step": validation.step, SCORE: kept, "validation": getattr(validation, metric)})

    config = trial_config(folder / BASE, fixed, params)
    owner = Owner(TRIAL, fingerprint(yaml.safe_dump(params, sort_keys=True)))
    with claim(out, owner, resuming=True):
        summary = Trainer(config, out, progress=False, on_validation=heard).run()
    best = summary.best_validation
    score = getattr(best, metric) if best is not None else math.nan
    tune.report({"step": summary.steps, SCORE: score, "finished": True})


def tuner(sweep: SweepFile, folder: Path, resume: bool, progress: bool) -> Any:
    """Tune's Tuner for the sweep in `folder`: new, or restored from folder/tune (new when the sweep
    was stopped before Tune saved its state). Without `progress`, Tune's console output is off (its
    new output engine ignores verbose=0). Tune leaves SIGINT to the command (`stop_tune`)."""
    if not progress:
        os.environ["RAY_AIR_NEW_OUTPUT"] = "0"
    os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = "1"
    from ray import tune

    trainable = tune.with_resources(
        tune.with_parameters(train_trial, folder=folder.resolve(), metric=sweep.metric, fixed=sweep.fixed),
        {"cpu": trial_config(folder / BASE, {}, {}).train.envs},
    )
    state = str((folder / TUNE).resolve())
    if resume and tune.Tuner.can_restore(state):
        return tune.Tuner.restore(state, trainable, restart_errored=True)
    return tune.Tuner(
        trainable,
        param_space=tune_space(sweep),
        tune_config=tune.TuneConfig(
            metric=SCORE,
            mode=sweep.mode,
            num_samples=sweep.samples,
            max_concurrent_trials=sweep.concurrent,
            reuse_actors=True,
        ),
        run_config=tune.RunConfig(
            name=TUNE, storage_path=str(folder.resolve()), verbose=1 if progress else 0
        ),
    )


def stop_tune() -> bool:
    """Ask Ray Tune's loop to stop as its own stop signal does (the handler it installs for SIGUSR1
    while `fit` runs): the running trials end, their run folders keep their last checkpoints, the
    experiment state is saved and `--resume` continues the unfinished trials. False before Tune
    listens. Tune's log lines about the stop are silenced: the report says it."""
    handler = signal.getsignal(signal.SIGUSR1)
    if not callable(handler):
        return False
    logging.getLogger("ray.tune").setLevel(logging.CRITICAL)
    handler(signal.SIGUSR1, None)
    return True


def sweep_and_report(sweep: SweepFile, base: Path, folder: Path, resume: bool, progress: bool) -> bool:
    """Run (or continue) the sweep in `folder` and write its report; True when trials are left
    unfinished (interrupted: `--resume` continues). The first SIGINT or SIGTERM stops Tune's loop
    (`stop_tune`), or the sweep before any trial when it comes before Tune listens; the others
    only wait for the report."""
    usr1 = signal.getsignal(signal.SIGUSR1)
    with deferred(interrupt_after=False):
        try:
            if not resume:
                prepare(sweep, base, folder)
            with stopped_by(stop_tune):
                results = tuner(sweep, folder, resume, progress).fit()
        except KeyboardInterrupt:
            print(f"interrupted before Tune ran the trials: `drivestack sweep --resume {folder}` runs them")
            return True
        finally:
            if usr1 is not None:  # Tune leaves its handler installed
                signal.signal(signal.SIGUSR1, usr1)
        return report(sweep, folder, tune_trials(results)) or received()


def tune_trials(results: Any) -> list[tuple[dict, dict, object]]:
    """(parameters, last metrics, error) of every trial in Tune's ResultGrid. A trial stopped before
    it reported (or started) has neither in its Result: its parameters and id come from Tune's
    record of the trial (the grid's private list of them, in the same order; Ray is pinned)."""
    records = results._experiment_analysis.trials
    return [
        (record.config, result.metrics or {"trial_id": record.trial_id}, result.error)
        for result, record in zip(results, records, strict=True)
    ]
