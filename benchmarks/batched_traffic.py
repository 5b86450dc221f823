"""Batched traffic (`stack.sim.batch`): world-frames per CPU-second of N worlds stepped together,
against the `vector` backend driving one world alone and stock highway-env, measured in one sitting;
and the memory of a batch of 256 worlds.

    .venv/bin/python benchmarks/batched_traffic.py [--scenario highway-v0] [--runs 3] [--frames 150]

Every path drives the same worlds (seeds 0, 1, ...) with the same ego actuation (easing off behind
the traffic: no world ends within the frames measured). stock: highway-env's `env.step` on the
stack's traffic (`drivestack/Highway-v0`, the stack's cheapest observation); vector:
`HighwayAdapter.step` on the `vector` backend, snapshot included; batch: `TrafficBatch.step` of N
worlds. The paths alternate run by run so that machine load hits them alike, after one short
warm-up run each (numba's kernels loaded); the figures are medians of `time.process_time` rates.
Resets are measured apart (CPU per world reset: the batch's `reset_world`, a stock env's `reset`)
and folded in as one reset per episode of the scenario's duration. Memory: the peak resident set
of a child process that builds and steps a batch of 256 worlds (`--memory-of 256`), and the bytes
its arrays hold.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import resource
import statistics
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np

from records import Actuation
from stack.settings.run import HighwayConfig, build_config
from stack.sim.batch.traffic import TrafficBatch
from stack.sim.envs import HIGHWAY
from stack.sim.highway import HighwayAdapter, env_config, to_env_action

SIZES = (1, 16, 64, 256)


def actuation(frame: int, world: int) -> tuple[float, float]:
    """The ego's acceleration [m/s^2] and steering [rad] at `frame` in world `world`: braking
    to a stop behind the traffic, straight (on highway-v0 nobody is behind it: no crash)."""
    return BRAKING, 0.0


BRAKING = -2.0
"""The egos' acceleration [m/s^2]."""


def batch_rate(highway: HighwayConfig, worlds: int, frames: int, intent: int = -1) -> float:
    """World-frames per CPU-second of a batch of `worlds` (resets at the start not counted), each
    ego showing the traffic the lane `intent` (-1: none) as the one it changes into."""
    batch = TrafficBatch(highway, worlds)
    batch.reset(list(range(worlds)))
    batch.arrays.intent[:] = intent
    steering = np.array([[actuation(frame, k)[1] for k in range(worlds)] for frame in range(frames)])
    acceleration = np.full(worlds, BRAKING)
    start = time.process_time()
    for frame in range(frames):
        ended = batch.step(acceleration, steering[frame])
        if ended.terminated.any() or ended.truncated.any():
            raise RuntimeError("a world ended: the steps measured would include a reset")
    elapsed = time.process_time() - start
    batch.close()
    return worlds * frames / elapsed


def vector_rate(highway: HighwayConfig, world: int, frames: int, intent: int = -1) -> float:
    """Frames per CPU-second of the vector backend driving world `world` alone, its ego showing the
    lane `intent` (-1: none) as the one it changes into."""
    adapter = HighwayAdapter(highway, backend="vector")
    adapter.reset(world)
    adapter.show_intent(intent)
    actuations = [Actuation(*actuation(frame, world)) for frame in range(frames)]
    start = time.process_time()
    for frame in range(frames):
        adapter.step(actuations[frame])
    elapsed = time.process_time() - start
    if adapter.done:
        raise RuntimeError("the episode ended: measure fewer frames")
    adapter.close()
    return frames / elapsed


def stock_rate(highway: HighwayConfig, world: int, frames: int) -> float:
    """Frames per CPU-second of highway-env's own `env.step` on world `world`."""
    env = gym.make(HIGHWAY, config=env_config(highway), disable_env_checker=True)
    env.reset(seed=world)
    actions = [to_env_action(Actuation(*actuation(frame, world))) for frame in range(frames)]
    start = time.process_time()
    for frame in range(frames):
        env.step(actions[frame])
    elapsed = time.process_time() - start
    env.close()
    return frames / elapsed


def reset_cost(highway: HighwayConfig, resets: int) -> tuple[float, float]:
    """CPU seconds of one world's reset: a batch's `reset_world` (highway-env's spawn, read into the
    arrays) and a stock env's `reset()`, each over `resets` seeds."""
    batch = TrafficBatch(highway, 1)
    start = time.process_time()
    for seed in range(resets):
        batch.reset_world(0, seed)
    batched = (time.process_time() - start) / resets
    batch.close()
    env = gym.make(HIGHWAY, config=env_config(highway), disable_env_checker=True)
    start = time.process_time()
    for seed in range(resets):
        env.reset(seed=seed)
    alone = (time.process_time() - start) / resets
    env.close()
    return batched, alone


def memory_of(highway: HighwayConfig, worlds: int, frames: int) -> None:
    """Print the peak resident set [MB] of this process after building and stepping a batch of
    `worlds` worlds `frames` frames, and the bytes [MB] its arrays hold."""
    batch = TrafficBatch(highway, worlds)
    batch.reset(list(range(worlds)))
    for frame in range(frames):
        batch.step(np.full(worlds, BRAKING), np.array([actuation(frame, k)[1] for k in range(worlds)]))
    arrays = sum(
        column.nbytes
        for table in (batch.arrays.columns, batch.arrays.lane_columns)
        for column in table.values()
    )
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{peak_mb:.0f} {arrays / 2**20:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenario", default="highway-v0")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--memory-of", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    highway = build_config({}, scenario=args.scenario).highway
    if args.memory_of:
        memory_of(highway, args.memory_of, args.frames)
        return
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, ", end="")
    print(f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, scenario {args.scenario}")
    stock_rate(highway, 0, 5), vector_rate(highway, 0, 5), batch_rate(highway, 2, 5)  # compiled, loaded
    rates: dict[str, list[float]] = {"stock": [], "vector": [], **{f"batch {n}": [] for n in SIZES}}
    for run in range(args.runs):
        rates["stock"].append(stock_rate(highway, run, args.frames))
        rates["vector"].append(vector_rate(highway, run, args.frames))
        for n in SIZES:
            rates[f"batch {n}"].append(batch_rate(highway, n, args.frames))
    median = {path: statistics.median(values) for path, values in rates.items()}
    batched_reset, alone_reset = reset_cost(highway, 10)
    episode = round(highway.duration * highway.simulation_frequency)

    def with_resets(rate: float, reset: float) -> float:
        return episode / (episode / rate + reset)

    stepped = {
        path: with_resets(rate, alone_reset if path in ("stock", "vector") else batched_reset)
        for path, rate in median.items()
    }
    print(f"| path | world-frames per CPU-s | / vector | / stock | with a reset per {episode} frames |")
    print("|---|---|---|---|---|")
    for path, rate in median.items():
        ratios = f"{rate / median['vector']:.1f}x | {rate / median['stock']:.1f}x"
        episodes = f"{stepped[path]:.0f} ({stepped[path] / stepped['vector']:.1f}x vector)"
        print(f"| {path} | {rate:.0f} | {ratios} | {episodes} |")
    print(
        f"reset of one world (CPU): batch {batched_reset * 1e3:.1f} ms, stock env {alone_reset * 1e3:.1f} ms"
    )
    command = [sys.executable, __file__, "--scenario", args.scenario, "--memory-of", "256"]
    peak, arrays = subprocess.run(command, capture_output=True, text=True, check=True).stdout.split()
    print(f"memory, 256 worlds: peak resident set {peak} MB (process), arrays {arrays} MB")


if __name__ == "__main__":
    main()
