"""Simulation backends: stock highway-env, drivestack's `fast` road and its `vector` road, frames/s
on one core, measured in one sitting.

    .venv/bin/python benchmarks/sim_speed.py [--runs 5] [--frames 300]

Each scene is stepped `--frames` physics frames with a constant action (ContinuousAction, one frame
per step, the stack's cheap observation) for seeds 0..runs-1, the three backends alternating seed by
seed so that machine load hits them alike; the figures are median frames/s and the ratios to stock.
The last column steps the vector road the way the closed loop does (`HighwayAdapter.step`: no
reward, observation or info dict, which the stack does not read), snapshot included.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

from records import Actuation
from stack.settings.run import HighwayConfig, build_config
from stack.sim.envs import FAST_HIGHWAY, HIGHWAY, VECTOR_HIGHWAY
from stack.sim.highway import HighwayAdapter, env_config

BACKENDS = {"stock": HIGHWAY, "fast": FAST_HIGHWAY, "vector": VECTOR_HIGHWAY}
SCENES = {
    "20 vehicles (4 lanes, 15 Hz)": HighwayConfig(vehicles_count=20),
    "highway-v0 defaults (4 lanes, 50 vehicles, 15 Hz)": HighwayConfig(),
    "100 vehicles, density 2 (4 lanes, 15 Hz)": HighwayConfig(vehicles_count=100, vehicles_density=2),
    "overtaking scenario (60 vehicles, trucks and cars)": build_config({}, scenario="overtaking").highway,
}


def frames_per_second(env_id: str, highway: HighwayConfig, seed: int, frames: int) -> float:
    env = gym.make(env_id, config={**env_config(highway), "duration": 1e6}, disable_env_checker=True)
    env.reset(seed=seed)
    action = np.zeros(2)
    rate = timed(lambda: env.step(action), frames)
    env.close()
    return rate


def stack_frames_per_second(highway: HighwayConfig, seed: int, frames: int) -> float:
    """Frames/s of the vector road stepped through the stack's adapter (snapshot included)."""
    adapter = HighwayAdapter(highway.model_copy(update={"duration": 1e6}), "vector")
    adapter.reset(seed)
    actuation = Actuation(0.0, 0.0)
    rate = timed(lambda: adapter.step(actuation), frames)
    adapter.close()
    return rate


def timed(step: Callable[[], object], frames: int) -> float:
    """Calls of `step` per second over `frames` calls."""
    start = time.perf_counter()
    for _ in range(frames):
        step()
    return frames / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--frames", type=int, default=300)
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}")
    print(
        "| scene | stock frames/s | fast frames/s | vector frames/s | fast / stock | vector / stock "
        "| vector, stack step / stock |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, highway in SCENES.items():
        rates: dict[str, list[float]] = {backend: [] for backend in (*BACKENDS, "stack")}
        for seed in range(args.runs):
            for backend, env_id in BACKENDS.items():
                rates[backend].append(frames_per_second(env_id, highway, seed, args.frames))
            rates["stack"].append(stack_frames_per_second(highway, seed, args.frames))
        stock, fast, vector, stack = (statistics.median(rates[b]) for b in rates)
        ratios = f"{fast / stock:.1f}x | {vector / stock:.1f}x | {stack / stock:.1f}x ({stack:.0f})"
        print(f"| {name} | {stock:.0f} | {fast:.0f} | {vector:.0f} | {ratios} |", flush=True)


if __name__ == "__main__":
    main()
