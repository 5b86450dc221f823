"""CPU a decision of the shipped training's batched worlds (`configs/train/ddqn.yaml`'s mix, as
`TrainingWorlds`), and a digest of what they returned, so two checkouts compare in one sitting:

    PYTHONPATH=TREE .venv/bin/python benchmarks/training_worlds.py [--worlds 32] [--decisions 300]
        [--seed 1024200] [--repeats 3]

The worlds are seeded with `--seed`, reset, and driven by commands drawn from a generator of seed 0
(the same commands in every tree); the first 30 decisions load numba's kernels and are not timed.
Each repeat rebuilds the worlds and prints its CPU seconds a decision and the digest of every
observation, reward and episode end (equal digests: the same episodes). Run two trees one after the
other, or alternately, on one machine: the ratio of their CPU is the figure, not the absolute value.
"""

from __future__ import annotations

import argparse
import hashlib
import time

import numpy as np

from stack.settings.run import load_config
from stack.training.batch_env import TrainingWorlds

WARM_UP_DECISIONS = 30
"""Decisions before the timing starts (numba's kernels loaded, the first episodes spawned)."""


def measure(worlds: int, decisions: int, seed: int) -> tuple[float, str]:
    """CPU seconds a world's decision over `decisions` steps of `worlds` worlds, and the digest."""
    config = load_config("configs/train/ddqn.yaml").model_copy(update={"seed": seed})
    env = TrainingWorlds(config, worlds)
    env.seed(seed)
    digest = hashlib.sha256(np.asarray(env.reset()).tobytes())
    commands = np.random.default_rng(0).integers(0, 3, (WARM_UP_DECISIONS + decisions, worlds))
    for command in commands[:WARM_UP_DECISIONS]:
        env.step(command)
    started = time.process_time()
    for command in commands[WARM_UP_DECISIONS:]:
        observations, rewards, done, _ = env.step(command)
        for array in (observations, rewards, done):
            digest.update(np.asarray(array).tobytes())
    spent = time.process_time() - started
    env.close()
    return spent / (decisions * worlds), digest.hexdigest()[:16]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worlds", type=int, default=32)
    parser.add_argument("--decisions", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1_024_200)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    for repeat in range(args.repeats):
        cpu, digest = measure(args.worlds, args.decisions, args.seed)
        spent = f"{cpu * 1e3:.3f} CPU-ms a world's decision ({args.worlds} worlds)"
        print(f"repeat {repeat + 1}: {spent}, digest {digest}")


if __name__ == "__main__":
    main()
