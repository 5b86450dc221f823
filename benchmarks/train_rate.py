"""Training throughput: environment steps (decisions) per second of `drivestack train` (DDQN, the
shipped config's lane network and action mask), on the `fast` and `vector` backends with 1 and 2
environments and on 64 batched worlds (`train.worlds`) in the learner's process and split over 2
worker processes (`train.envs` 2), in one sitting.

    .venv/bin/python benchmarks/train_rate.py [--steps 1500] [--world-steps 40000]
        [--replay-ratio 0.0625] [--scenario overtaking] [--profile]

Every variant drives the one world `--scenario` (not the config's mix) through the config's grid,
with validation, checkpoints and demonstrations out of the way. The per-world ones train `--steps`
steps (the first 500 fill the buffer, then one gradient step per transition); the batched ones
`--world-steps` with `--replay-ratio` gradient steps per decision (of the config's batch size).
Two figures: steps / wall seconds with start-up (env processes, model, replay buffer, the shards'
first steps) included, and the steady state a long run sees (the last two thirds of the steps); for
the variants in one process also steps per CPU-second (a machine's load barely moves it; '-' where
env processes work too, whose CPU time this process does not see).
With `--profile`, the `vector, 2 envs` variant alone, its wall time split between waiting for the
env processes' steps, handing them the actions, the gradient steps, the start-up (env processes,
model) and the rest.
"""

from __future__ import annotations

import argparse
import collections
import platform
import resource
import tempfile
import time
from pathlib import Path

from loop_profile import instrument
from stable_baselines3.common.monitor import Monitor

from stack.settings.run import NULL, load_config
from stack.training.trainer import Trainer

WORLDS = 64
"""Worlds of the batched variant."""
VARIANTS = [
    ("fast", 1, None, False),
    ("vector", 1, None, False),
    ("vector", 2, None, False),
    ("vector", 1, WORLDS, False),
    ("vector", 2, WORLDS, False),
    ("vector", 2, WORLDS, True),
    ("vector", 2, 2 * WORLDS, True),
]
"""(backend, env processes, batched worlds or None, `train.overlap`)."""
COMPONENTS = [
    ["waiting for the env processes' steps", "stable_baselines3.common.vec_env:SubprocVecEnv.step_wait"],
    ["handing the env processes the actions", "stable_baselines3.common.vec_env:SubprocVecEnv.step_async"],
    ["gradient steps (DoubleDQN.train)", "planner.ddqn:DoubleDQN.train"],
    ["start-up (env processes, model, warm start)", "stack.training.trainer:Trainer.__init__"],
]
"""(label, module:Owner.method) whose wall time the profile adds up."""


def cpu_seconds() -> float:
    """CPU time [s] of this process (not of env worker processes, which the forkserver starts)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime


def timed_steps(trainer: Trainer) -> list[float]:
    """The times [s] at which each step of `trainer`'s env ends, filled as it runs."""
    marks: list[float] = []
    env = trainer.env
    name = "step" if isinstance(env, Monitor) else "step_wait"
    step = getattr(env, name)

    def timed(*args: object) -> object:
        result = step(*args)
        marks.append(time.perf_counter())
        return result

    setattr(env, name, timed)
    return marks


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--world-steps", type=int, default=40_000, help="steps of the batched variant")
    parser.add_argument("--replay-ratio", type=float, default=1 / 16, help="of the batched variant")
    parser.add_argument("--scenario", default="overtaking")
    parser.add_argument("--config", default="configs/train/ddqn.yaml")
    parser.add_argument("--profile", action="store_true", help="where the wall time of 2 envs goes")
    args = parser.parse_args()
    print(f"{platform.machine()}, Python {platform.python_version()}, scenario {args.scenario}")
    spent: collections.Counter[str] = collections.Counter()
    if args.profile:
        instrument(spent, COMPONENTS, time.perf_counter_ns)
    print(
        "| backend | envs | gradient steps / decision | env steps/s | vs fast, 1 env "
        "| after start-up | per CPU-s |"
    )
    print("|---|---|---|---|---|---|---|")
    baseline = None
    for backend, envs, worlds, overlap in VARIANTS[2:3] if args.profile else VARIANTS:
        steps = args.world_steps if worlds else args.steps
        ratio = args.replay_ratio if worlds else 1.0
        never = 10 * steps
        config = load_config(
            args.config,
            scenario=args.scenario,
            sim__backend=backend,
            train__scenarios={},
            train__envs=envs,
            train__demonstrations=NULL,
            train__overlap=overlap,
            train__worlds=worlds or NULL,
            train__replay_ratio=ratio,
            train__steps=steps,
            train__learning_starts=500,
            train__checkpoint_every=never,
            train__validation__short_every=never,
            train__validation__long_every=never,
        )
        with tempfile.TemporaryDirectory() as out:
            start, cpu = time.perf_counter(), cpu_seconds()
            trainer = Trainer(config, Path(out), progress=False)
            marks = timed_steps(trainer)
            trainer.run()
            wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu
        first = len(marks) // 3
        rate = steps / wall
        steady = (len(marks) - 1 - first) * config.train.parallel / (marks[-1] - marks[first])
        baseline = baseline or rate
        named = str(envs)
        if worlds:
            named = f"{worlds} batched worlds" + (f" in {envs} processes" if envs > 1 else "")
            named += ", learning while they step" if overlap else ""
        per_cpu = f"{steps / cpu:.1f}" if envs == 1 else "-"
        row = f"| {backend} | {named} | {ratio:g} | {rate:.1f} | {rate / baseline:.2f}x | {steady:.1f} "
        row += f"| {per_cpu} |"
        print(row, flush=True)
    if args.profile:
        print(f"\n| component (wall, {args.steps} steps) | s | ms per env step | share |\n|---|---|---|---|")
        seconds_in = {label: ns / 1e9 for label, ns in spent.items()}
        for label, seconds in [*seconds_in.items(), ("rest", wall - sum(seconds_in.values()))]:
            per_step, share = 1e3 * seconds / args.steps, 100 * seconds / wall
            print(f"| {label} | {seconds:.1f} | {per_step:.2f} | {share:.0f} % |")


if __name__ == "__main__":
    main()
