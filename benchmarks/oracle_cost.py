"""Cost of the oracle's two-decision search per episode on the `fast` and the `vector` backend, in one
sitting, with a check that both drive the same episode.

    .venv/bin/python benchmarks/oracle_cost.py [--seeds 0,1] [--scenario overtaking]

CPU seconds (process time) of whole 40-s episodes of `--agent oracle`, the backends alternating
seed by seed; the episode summaries must be identical, since both backends are bit-identical to stock.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import time

from stack.core.config import build_config
from stack.core.episodes import run_episode
from stack.core.metrics import TIMING_FIELDS


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--scenario", default="overtaking")
    parser.add_argument("--duration", type=float, default=40.0, help="episode length [s]")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    print(
        f"{platform.machine()}, Python {platform.python_version()}, scenario {args.scenario}, seeds {seeds}"
    )
    cost: dict[str, float] = {"fast": 0.0, "vector": 0.0}
    for seed in seeds:
        results = {}
        for backend in cost:
            config = build_config(
                {"planner": {"agent": "oracle"}, "sim": {"backend": backend}, "seed": seed},
                scenario=args.scenario,
                highway__duration=args.duration,
            )
            start = time.process_time()
            episode = run_episode(config, 0)
            record = {
                f.name: getattr(episode, f.name)
                for f in dataclasses.fields(episode)
                if f.name not in ("snapshot", *TIMING_FIELDS)
            }
            results[backend] = json.dumps(record, default=lambda value: value.tolist())
            cost[backend] += time.process_time() - start
            print(f"seed {seed} {backend}: {time.process_time() - start:.1f} s CPU", flush=True)
        assert results["fast"] == results["vector"], f"seed {seed}: the backends drove different episodes"
    fast, vector = (cost[b] / len(seeds) for b in cost)
    print("| backend | CPU s per oracle episode | ratio |")
    print("|---|---|---|")
    print(f"| fast | {fast:.1f} | 1.00 |")
    print(f"| vector | {vector:.1f} | {fast / vector:.2f}x cheaper |")


if __name__ == "__main__":
    main()
