"""Control-tick rate of the closed loop next to highway-env's bare frame rate on the same config.

    .venv/bin/python benchmarks/loop_rate.py [--episodes 3] [--config configs/highway.yaml]

Bare: `env.step` with a constant action on stock highway-v0 set up as the adapter sets it
(ContinuousAction, one frame per step, the cheap observation) and with highway-env's default
Kinematics observation. Loop: the full stack (snapshot, grid, agent, controller, metrics) on each
backend. One process, one core; medians over
episodes (seeds 0..N-1).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import gymnasium as gym
import numpy as np

from planner.factory import make_agent
from stack.core.closed_loop import ClosedLoop, grid_config
from stack.core.config import load_config
from stack.core.episodes import run_agent_episode
from stack.sim.highway import HighwayAdapter, env_config


def bare_rate(config: dict, seeds: range) -> float:
    env = gym.make("highway-v0", config=config, disable_env_checker=True)
    rates = []
    for seed in seeds:
        env.reset(seed=seed)
        frames, start, done = 0, time.perf_counter(), False
        while not done:
            _, _, terminated, truncated, _ = env.step(np.zeros(2))
            frames += 1
            done = terminated or truncated
        rates.append(frames / (time.perf_counter() - start))
    env.close()
    return statistics.median(rates)


def loop_rate(run_config, seeds: range) -> float:
    rates = []
    with HighwayAdapter(run_config.highway, run_config.sim.backend) as adapter:
        agent = make_agent(run_config.planner.agent, run_config.highway.lanes_count, grid_config(run_config))
        for seed in seeds:
            start = time.perf_counter()
            loop = ClosedLoop(run_config, adapter, grid=agent.grid_config)
            result = run_agent_episode(loop, agent, 0, seed)
            rates.append(result.steps / (time.perf_counter() - start))
    return statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--config", default="configs/highway.yaml")
    parser.add_argument("--episodes", type=int, default=3)
    args = parser.parse_args()
    config = load_config(args.config)
    seeds = range(args.episodes)
    stack_env = env_config(config.highway)
    stock_env = {k: v for k, v in stack_env.items() if k != "observation"}
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"bare highway-env, stack config (cheap observation): {bare_rate(stack_env, seeds):7.1f} frames/s")
    print(f"bare highway-env, Kinematics observation:          {bare_rate(stock_env, seeds):7.1f} frames/s")
    for backend in ("stock", "fast", "vector"):
        backend_config = config.model_copy(update={"sim": config.sim.model_copy(update={"backend": backend})})
        rate = loop_rate(backend_config, seeds)
        print(
            f"closed loop ({config.planner.agent} + {config.controller.type}), {backend:5} backend:"
            f"   {rate:7.1f} ticks/s"
        )


if __name__ == "__main__":
    main()
