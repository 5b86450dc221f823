"""Training throughput: environment steps per second of `drivestack train` (DDQN, the shipped
config), on the `fast` and `vector` backends with 1 and 2 environments, in one sitting.

    .venv/bin/python benchmarks/train_rate.py [--steps 1500] [--scenario overtaking]

Each variant trains `--steps` steps (the first 500 fill the buffer, then one gradient step per
transition) with validation and checkpoints out of the way; the figure is steps / wall seconds,
process start-up of the parallel environments included.
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

from stack.core.config import load_config
from stack.training.trainer import Trainer

VARIANTS = [("fast", 1), ("vector", 1), ("vector", 2)]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--scenario", default="overtaking")
    parser.add_argument("--config", default="configs/train/ddqn-stage1.yaml")
    args = parser.parse_args()
    print(f"{platform.machine()}, Python {platform.python_version()}, scenario {args.scenario}")
    print("| backend | envs | env steps/s | vs fast, 1 env |")
    print("|---|---|---|---|")
    baseline = None
    for backend, envs in VARIANTS:
        never = 10 * args.steps
        config = load_config(
            args.config,
            scenario=args.scenario,
            sim__backend=backend,
            train__envs=envs,
            train__steps=args.steps,
            train__learning_starts=500,
            train__checkpoint_every=never,
            train__validation__short_every=never,
            train__validation__long_every=never,
        )
        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            Trainer(config, Path(out), progress=False).run()
            rate = args.steps / (time.perf_counter() - start)
        baseline = baseline or rate
        print(f"| {backend} | {envs} | {rate:.1f} | {rate / baseline:.2f}x |", flush=True)


if __name__ == "__main__":
    main()
