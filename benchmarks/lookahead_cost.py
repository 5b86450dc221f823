"""CPU time of the lookahead agent's decisions in closed loop: the agent's `predict` (reading its grid
back into vehicles, the safety check, the compiled rollout of every permitted command, the score),
and, apart, perception's build of its 3 x 130-cell grid, per decision, p50 / p95 / max.

    .venv/bin/python benchmarks/lookahead_cost.py [--episodes 3] [--duration 40] [--scenarios jam,...]

Seeded episodes (seeds 0..N-1) of every named scenario (default), one process, one core; the first
episode of each scenario runs first untimed (imports and the compiled rollout loaded, as in any run
of more than one episode). CPU time is process time, so another process's load does not count.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from planner.agents import decide
from stack.loop.closed_loop import ClosedLoop
from stack.runs.kept import build_agent
from stack.settings.run import build_config
from stack.sim.highway import HighwayAdapter
from stack.worlds import scenarios


def decision_times(scenario: str, episodes: int, duration: float) -> tuple[list[float], list[float]]:
    """(agent ms, grid ms) per decision over `episodes` seeded episodes of `scenario`."""
    config = build_config({"planner": {"agent": "lookahead"}, "seed": 0}, scenario=scenario)
    config = config.model_copy(update={"highway": config.highway.model_copy(update={"duration": duration})})
    agent_ms: list[float] = []
    grid_ms: list[float] = []
    with HighwayAdapter(config.highway, config.sim.backend, plant=config.sim.plant) as adapter:
        for seed in range(-1, episodes):
            agent = build_agent(config, max(seed, 0))
            loop = ClosedLoop(config, adapter, grid=agent.grid_config)
            loop.reset(max(seed, 0))
            while not loop.done:
                start = time.process_time()
                grid = loop.perceive()
                built = time.process_time()
                command = decide(agent, grid.encode(agent.encoding))
                decided = time.process_time()
                if seed >= 0:
                    grid_ms.append(1e3 * (built - start))
                    agent_ms.append(1e3 * (decided - built))
                loop.act(command)
    return agent_ms, grid_ms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--duration", type=float, default=40.0, help="episode length [s]")
    parser.add_argument("--scenarios", default=",".join(scenarios.names()))
    arguments = parser.parse_args()
    print(f"machine: {platform.machine()} {platform.processor() or ''}, python {platform.python_version()}")
    print("| scenario | decisions | agent p50 ms | agent p95 ms | agent max ms | grid p50 ms | grid p95 ms |")
    print("|---|---|---|---|---|---|---|")
    everything: list[float] = []
    for scenario in arguments.scenarios.split(","):
        agent_ms, grid_ms = decision_times(scenario, arguments.episodes, arguments.duration)
        everything += agent_ms
        a50, a95, amax = np.percentile(agent_ms, [50, 95, 100])
        g50, g95 = np.percentile(grid_ms, [50, 95])
        print(
            f"| {scenario} | {len(agent_ms)} | {a50:.3f} | {a95:.3f} | {amax:.3f} | {g50:.3f} | {g95:.3f} |"
        )
    p50, p95 = np.percentile(everything, [50, 95])
    print(
        f"all {len(everything)} decisions: agent p50 {p50:.3f} ms, p95 {p95:.3f} ms CPU (target p95 <= 2 ms)"
    )


if __name__ == "__main__":
    main()
