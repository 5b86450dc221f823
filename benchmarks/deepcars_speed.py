"""DeepCars batch env throughput on one core.

    .venv/bin/python benchmarks/deepcars_speed.py

Steps a `DeepCarsBatch` of 1, 64 and 1024 envs with random actions for ~2 s each; env steps/s.
"""

from __future__ import annotations

import time

import numpy as np

from records import N_ACTIONS
from stack.deepcars.world import DeepCarsBatch


def main() -> None:
    rng = np.random.default_rng(0)
    print("| envs in the batch | env steps/s |")
    print("|---|---|")
    for n in (1, 64, 1024):
        batch = DeepCarsBatch(n, seed=0)
        actions = rng.integers(0, N_ACTIONS, (256, n))
        steps, start = 0, time.perf_counter()
        while time.perf_counter() - start < 2.0:
            for a in actions:
                batch.step(a)
            steps += len(actions) * n
        print(f"| {n} | {steps / (time.perf_counter() - start):,.0f} |")


if __name__ == "__main__":
    main()
