"""Control-tick rate of the closed loop next to highway-env's bare frame rate on the same config,
and the CPU cost of whole seeded episodes per backend.

    .venv/bin/python benchmarks/loop_rate.py [--episodes 3] [--config configs/highway.yaml]
    .venv/bin/python benchmarks/loop_rate.py --cpu [--episodes 3] [--scenario highway-v0] [--agent mobil]
        [--tracker auto|on|off]

With `--cpu`: the CPU time (process time) of `run_episode` on the same seeded `--duration`-s
episodes of `--agent` with `--backend stock` and the default `vector`, the backends alternating
episode by episode (so machine load hits them alike), as ms per frame and the ratio; the episodes'
results must be identical on both.

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
from stack.loop.closed_loop import ClosedLoop, grid_config
from stack.runs.alone import run_agent_episode
from stack.settings.run import load_config
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


def episode_cpu(scenario: str, agent: str, episodes: int, duration: float, tracker: str = "auto") -> None:
    """CPU ms per frame of the same seeded episodes on the stock and the vector backend."""
    from stack.results.episode_result import TIMING_FIELDS
    from stack.runs.episodes import run_episode
    from stack.settings.run import build_config

    configs = {
        backend: build_config(
            {
                "planner": {"agent": agent},
                "sim": {"backend": backend},
                "seed": 0,
                "perception": {"tracker": {"mode": tracker}},
            },
            scenario=scenario,
            highway__duration=duration,
        )
        for backend in ("stock", "vector")
    }
    for config in configs.values():
        run_episode(config, episodes)  # imports, caches and the process's env warmed up
    cpu = dict.fromkeys(configs, 0.0)
    frames = 0
    for episode in range(episodes):
        rows = {}
        for backend, config in configs.items():
            start = time.process_time()
            result = run_episode(config, episode)
            cpu[backend] += time.process_time() - start
            rows[backend] = {k: v for k, v in result.row().items() if k not in TIMING_FIELDS}
        assert rows["stock"] == rows["vector"], f"episode {episode}: the backends drove different episodes"
        frames += result.steps
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"{episodes} x {duration:g}-s {agent} episodes on {scenario} (tracker {tracker}), {frames} frames")
    print("| backend | CPU s | ms per frame | ratio |\n|---|---|---|---|")
    for backend in cpu:
        ratio = cpu["stock"] / cpu[backend]
        print(f"| {backend} | {cpu[backend]:.2f} | {1e3 * cpu[backend] / frames:.3f} | {ratio:.1f}x |")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--config", default="configs/highway.yaml")
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--cpu", action="store_true", help="CPU per frame of whole episodes, stock vs vector")
    parser.add_argument("--scenario", default="highway-v0")
    parser.add_argument("--agent", default="mobil")
    parser.add_argument("--duration", type=float, default=15.0, help="episode length [s] with --cpu")
    parser.add_argument(
        "--tracker", default="auto", help="with --cpu: perception.tracker.mode (auto | on | off)"
    )
    args = parser.parse_args()
    if args.cpu:
        episode_cpu(args.scenario, args.agent, args.episodes, args.duration, args.tracker)
        return
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
