"""Batched decisions (`stack.training.gym_vector_env.DecisionVecEnv` over `DecisionBatch`): decisions of
the decision MDP per CPU-second, N worlds stepped together against one world of the per-world env
(`HierarchicalHighwayEnv` on the `vector` backend), measured in one sitting.

    .venv/bin/python benchmarks/batched_decisions.py [--scenario highway-v0] [--runs 3] [--episodes 1]
        [--duration S] [--sizes 1,16,64,256] [--sides] [--tracker auto|on|off]

`--sides`: the grid of one size on every road (`lanes: ego`, `lane_code: sides`), which `random`
(2-6 lanes an episode) needs.

Both paths take seeded random commands (the agent's cost is not measured) and run whole episodes
(`--episodes` of the scenario's duration, one decision a second), so each world's reset (highway-env
spawning its road) is counted once an episode, as training pays it. The paths alternate run by
run, so machine load hits them alike, after a short warm-up each (numba's kernels loaded); the
figures are medians of `time.process_time` rates. One process on one core: two cores run two
such processes (N worlds each) for twice the decisions.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import statistics
import time

import numpy as np

from stack.settings.run import RunConfig, build_config
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.gym_vector_env import DecisionVecEnv

SIZES = (1, 16, 64, 256)


def decisions_per_episode(config: RunConfig) -> int:
    """Decisions of one episode that runs its full duration (the last one ends it)."""
    return round(config.highway.duration / config.decision_period_s) + 1


def alone_rate(config: RunConfig, run: int, decisions: int) -> float:
    """Decisions per CPU-second of one per-world env, resets included."""
    env = HierarchicalHighwayEnv(config)
    env.reset(seed=run)
    commands = np.random.default_rng(run).integers(0, 3, decisions)
    start = time.process_time()
    for command in commands.tolist():
        _, _, terminated, truncated, _ = env.step(command)
        if terminated or truncated:
            env.reset()
    elapsed = time.process_time() - start
    env.close()
    return decisions / elapsed


def batch_rate(config: RunConfig, worlds: int, run: int, steps: int) -> float:
    """Decisions per CPU-second of `worlds` worlds stepped together, same-step resets included."""
    env = DecisionVecEnv(config, worlds, seed=run)
    env.reset()
    commands = np.random.default_rng(run).integers(0, 3, (steps, worlds))
    start = time.process_time()
    for step in range(steps):
        env.step(commands[step])
    elapsed = time.process_time() - start
    env.close()
    return worlds * steps / elapsed


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenario", default="highway-v0")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--duration", type=float, help="episode duration [s] (default: the scenario's)")
    parser.add_argument("--sizes", default=",".join(map(str, SIZES)), help="batch sizes, comma-separated")
    parser.add_argument("--sides", action="store_true", help="perception lanes: ego, lane_code: sides")
    parser.add_argument("--tracker", default="auto", help="perception.tracker.mode: auto | on | off")
    args = parser.parse_args()
    data: dict = {"highway": {"duration": args.duration}} if args.duration else {}
    data["perception"] = {"tracker": {"mode": args.tracker}}
    if args.sides:
        data["perception"] |= {"lanes": "ego", "lane_code": "sides"}
    config = build_config(data, scenario=args.scenario)
    sizes = [int(size) for size in args.sizes.split(",")]
    steps = args.episodes * decisions_per_episode(config)
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, ", end="")
    now = datetime.datetime.now(datetime.UTC)
    print(
        f"{now:%Y-%m-%d %H:%M} UTC, scenario {args.scenario}, tracker {args.tracker}, "
        f"{steps} decisions a world"
    )
    alone_rate(config, 0, 3), batch_rate(config, 2, 0, 3)  # compiled, loaded
    rates: dict[str, list[float]] = {"alone": [], **{f"batch {n}": [] for n in sizes}}
    for run in range(args.runs):
        rates["alone"].append(alone_rate(config, run, steps))
        for n in sizes:
            rates[f"batch {n}"].append(batch_rate(config, n, run, steps))
    median = {path: statistics.median(values) for path, values in rates.items()}
    print("| path | decisions per CPU-s | / alone |")
    print("|---|---|---|")
    for path, rate in median.items():
        print(f"| {path} | {rate:.0f} | {rate / median['alone']:.1f}x |")


if __name__ == "__main__":
    main()
