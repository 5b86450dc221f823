"""Training throughput: environment steps (decisions) per second of `drivestack train` (DDQN, the
shipped network), on the `fast` and `vector` backends with 1 and 2 environments and on 64 batched
worlds (`train.worlds`) in the learner's process and split over 2 worker processes (`train.envs`
2), in one sitting.

    .venv/bin/python benchmarks/train_rate.py [--steps 1500] [--world-steps 20000]
        [--replay-ratio 0.0625] [--scenario overtaking] [--profile]

Every variant drives the one world `--scenario` (not the config's mix) seen through the grid
features the batch encodes, with validation and checkpoints out of the way. The per-world ones
train `--steps` steps (the first 500 fill the buffer, then one gradient step per transition); the
batched ones `--world-steps` with `--replay-ratio` gradient steps per decision (batch size 64 each).
The figure is steps / wall seconds, start-up (env processes, model, replay buffer) included, and
for the variants in one process steps per CPU-second (a machine's load barely moves it; '-' where
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

from perception.batch_grid import BATCHED_FEATURES
from stack.settings.run import load_config
from stack.training.trainer import Trainer

WORLDS = 64
"""Worlds of the batched variant."""
VARIANTS = [
    ("fast", 1, None),
    ("vector", 1, None),
    ("vector", 2, None),
    ("vector", 1, WORLDS),
    ("vector", 2, WORLDS),
]
"""(backend, env processes, batched worlds or None)."""
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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--world-steps", type=int, default=20_000, help="steps of the batched variant")
    parser.add_argument("--replay-ratio", type=float, default=1 / 16, help="of the batched variant")
    parser.add_argument("--scenario", default="overtaking")
    parser.add_argument("--config", default="configs/train/ddqn-stage1.yaml")
    parser.add_argument("--profile", action="store_true", help="where the wall time of 2 envs goes")
    args = parser.parse_args()
    print(f"{platform.machine()}, Python {platform.python_version()}, scenario {args.scenario}")
    spent: collections.Counter[str] = collections.Counter()
    if args.profile:
        instrument(spent, COMPONENTS, time.perf_counter_ns)
    print("| backend | envs | gradient steps / decision | env steps/s | vs fast, 1 env | per CPU-s |")
    print("|---|---|---|---|---|---|")
    baseline = None
    for backend, envs, worlds in VARIANTS[2:3] if args.profile else VARIANTS:
        steps = args.world_steps if worlds else args.steps
        ratio = args.replay_ratio if worlds else 1.0
        never = 10 * steps
        config = load_config(
            args.config,
            scenario=args.scenario,
            sim__backend=backend,
            perception__features=list(BATCHED_FEATURES),
            train__scenarios={},
            train__envs=envs,
            train__worlds=worlds,
            train__replay_ratio=ratio,
            train__steps=steps,
            train__learning_starts=500,
            train__checkpoint_every=never,
            train__validation__short_every=never,
            train__validation__long_every=never,
        )
        with tempfile.TemporaryDirectory() as out:
            start, cpu = time.perf_counter(), cpu_seconds()
            Trainer(config, Path(out), progress=False).run()
            wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu
        rate = steps / wall
        baseline = baseline or rate
        named = str(envs)
        if worlds:
            named = f"{worlds} batched worlds" + (f" in {envs} processes" if envs > 1 else "")
        per_cpu = f"{steps / cpu:.1f}" if envs == 1 else "-"
        row = f"| {backend} | {named} | {ratio:g} | {rate:.1f} | {rate / baseline:.2f}x | {per_cpu} |"
        print(row, flush=True)
    if args.profile:
        print(f"\n| component (wall, {args.steps} steps) | s | ms per env step | share |\n|---|---|---|---|")
        seconds_in = {label: ns / 1e9 for label, ns in spent.items()}
        for label, seconds in [*seconds_in.items(), ("rest", wall - sum(seconds_in.values()))]:
            per_step, share = 1e3 * seconds / args.steps, 100 * seconds / wall
            print(f"| {label} | {seconds:.1f} | {per_step:.2f} | {share:.0f} % |")


if __name__ == "__main__":
    main()
