"""Simulation backends: stock highway-env vs drivestack's fast road, frames/s on one core.

    .venv/bin/python benchmarks/sim_speed.py [--runs 5] [--frames 300]

Each scene is stepped `--frames` physics frames with a constant action (ContinuousAction, one frame
per step, the stack's cheap observation) for seeds 0..runs-1, alternating stock and fast; the
figure is the median frames/s, the ratio fast/stock.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import highway_env  # noqa: F401
import numpy as np

from stack.core.config import HighwayConfig
from stack.sim.envs import FAST_HIGHWAY, FAST_HIGHWAY_FAST
from stack.sim.highway import env_config

SCENES = {
    "highway-v0 defaults (4 lanes, 50 vehicles, 15 Hz)": (
        "highway-v0",
        FAST_HIGHWAY,
        env_config(HighwayConfig()),
    ),
    "highway-fast-v0 traffic (3 lanes, 20 vehicles, 5 Hz, ego-only collisions)": (
        "highway-fast-v0",
        FAST_HIGHWAY_FAST,
        env_config(HighwayConfig(lanes_count=3, vehicles_count=20, simulation_frequency=5)),
    ),
    "100 vehicles, density 2 (4 lanes, 15 Hz)": (
        "highway-v0",
        FAST_HIGHWAY,
        env_config(HighwayConfig(vehicles_count=100, vehicles_density=2)),
    ),
}


def frames_per_second(env_id: str, config: dict, seed: int, frames: int) -> float:
    env = gym.make(env_id, config={**config, "duration": 1e6}, disable_env_checker=True)
    env.reset(seed=seed)
    action = np.zeros(2)
    start = time.perf_counter()
    for _ in range(frames):
        env.step(action)
    rate = frames / (time.perf_counter() - start)
    env.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--frames", type=int, default=300)
    args = parser.parse_args()
    print("| scene | stock frames/s | fast frames/s | fast / stock |")
    print("|---|---|---|---|")
    for name, (stock_id, fast_id, config) in SCENES.items():
        stock, fast = [], []
        for seed in range(args.runs):
            stock.append(frames_per_second(stock_id, config, seed, args.frames))
            fast.append(frames_per_second(fast_id, config, seed, args.frames))
        s, f = statistics.median(stock), statistics.median(fast)
        print(f"| {name} | {s:.0f} | {f:.0f} | {f / s:.2f}x |", flush=True)


if __name__ == "__main__":
    main()
