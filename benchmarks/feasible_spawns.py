"""Feasible spawns: keep-lane on `dense` and `jam`, 1,000 seeds each, counted collisions in the
first 3 s (no agent can be blamed for a crash its start made unavoidable).

.venv/bin/python benchmarks/feasible_spawns.py [--episodes 1000] [--seed 700000] [--jobs 2]
"""

from __future__ import annotations

import argparse
import time

from stack.runs.episodes import run
from stack.settings.run import build_config

SCENARIOS = ("dense", "jam")
FIRST_SECONDS = 3.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=700_000)
    parser.add_argument("--jobs", type=int, default=2)
    arguments = parser.parse_args()
    print("| scenario | episodes | collisions in the first 3 s | at fault | wall s |")
    print("|---|---|---|---|---|")
    for scenario in SCENARIOS:
        config = build_config(
            {"episodes": arguments.episodes, "seed": arguments.seed, "planner": {"agent": "keep-lane"}},
            scenario=scenario,
            highway__duration=FIRST_SECONDS,
        )
        start = time.perf_counter()
        summary = run(config, progress=False, jobs=arguments.jobs).summary
        wall = time.perf_counter() - start
        print(
            f"| {scenario} | {summary['episodes']} | {summary['collisions']} | "
            f"{summary['at_fault_collisions']} | {wall:.0f} |"
        )


if __name__ == "__main__":
    main()
