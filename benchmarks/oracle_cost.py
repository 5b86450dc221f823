"""Cost of the oracle's two-decision search per episode on the `fast` and the `vector` backend, in one
sitting, with a check that both drive the same episode.

    .venv/bin/python benchmarks/oracle_cost.py [--seeds 0,1] [--scenario overtaking] [--backends fast,vector]
        [--profile] [--forks]

CPU seconds (process time) of whole 40-s episodes of `--agent oracle`, the backends alternating
seed by seed, after a 2-s episode in the same process (imports and compiled kernels loaded); the
episode summaries must be identical, since both backends are bit-identical to stock. With one
backend (`--backends vector`), its cost per episode alone, and a digest of each episode's record
(to compare two trees: run this file with each tree on the `PYTHONPATH`). With `--forks`, the search
plays its rollouts on forks of the loop one at a time, as for a loop that cannot be copied into a
batch (`stack.agents.oracle_search.search_refusal`), rather than as one batch of worlds: run it with
and without to compare the two in one tree (the same digests: the same decisions).
With `--profile`, the first seed's episode on `vector` alone, after a 2-s episode in the same process
(imports and compiled kernels loaded), its CPU time split between the search's parts.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import hashlib
import json
import platform
import time

from loop_profile import instrument

from stack.agents import oracle
from stack.results.episode_result import TIMING_FIELDS
from stack.runs.episodes import run_episode
from stack.settings.run import build_config

COMPONENTS = [
    ["search (`Oracle.plan`)", "stack.agents.oracle:Oracle.plan"],
    ["copies of the loop (`ClosedLoop.fork`)", "stack.loop.closed_loop:ClosedLoop.fork"],
    ["control ticks (the rollouts' and the episode's)", "stack.loop.closed_loop:ClosedLoop.tick"],
    ["base agent's decisions (Q-network)", "planner.learned:LearnedAgent.choose"],
    ["grids the base agent sees", "perception.grid:OccupancyGridBuilder.build"],
]
"""(label, module:Owner.method) whose CPU time the profile adds up; all but the first run inside it."""


def profile(scenario: str, seed: int, duration: float) -> None:
    """CPU seconds of one oracle episode by part, the parts nested in the search."""
    config = {"planner": {"agent": "oracle"}, "sim": {"backend": "vector"}, "seed": seed}
    run_episode(build_config(config, scenario=scenario, highway__duration=2.0), 1)
    spent: collections.Counter[str] = collections.Counter()
    instrument(spent, COMPONENTS)
    start = time.process_time()
    run_episode(build_config(config, scenario=scenario, highway__duration=duration), 0)
    whole = time.process_time() - start
    print(
        f"{platform.machine()}, Python {platform.python_version()}, {scenario}, seed {seed}, {duration:g} s"
    )
    print("| part | CPU s | share |\n|---|---|---|")
    print(f"| whole episode | {whole:.2f} | 100 % |")
    for label, _ in COMPONENTS:
        print(f"| {label} | {spent[label] / 1e9:.2f} | {100 * spent[label] / 1e9 / whole:.0f} % |")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--scenario", default="overtaking")
    parser.add_argument("--duration", type=float, default=40.0, help="episode length [s]")
    parser.add_argument("--backends", default="fast,vector", help="comma-separated: fast, vector")
    parser.add_argument("--profile", action="store_true", help="the first seed's episode by part")
    parser.add_argument("--forks", action="store_true", help="the search's rollouts on forks, not a batch")
    args = parser.parse_args()
    if args.forks:
        oracle.search_refusal = lambda loop, base: "rollouts on forks (--forks)"
    seeds = [int(s) for s in args.seeds.split(",")]
    if args.profile:
        profile(args.scenario, seeds[0], args.duration)
        return
    print(
        f"{platform.machine()}, Python {platform.python_version()}, scenario {args.scenario}, seeds {seeds}"
    )
    cost: dict[str, float] = dict.fromkeys(args.backends.split(","), 0.0)
    for backend in cost:
        warm = {"planner": {"agent": "oracle"}, "sim": {"backend": backend}, "seed": seeds[0]}
        run_episode(build_config(warm, scenario=args.scenario, highway__duration=2.0), 1)
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
        if len(cost) == 1:
            digest = hashlib.sha256(next(iter(results.values())).encode()).hexdigest()[:16]
            print(f"seed {seed} episode digest: {digest}")
            continue
        assert results["fast"] == results["vector"], f"seed {seed}: the backends drove different episodes"
    if len(cost) == 1:
        backend, spent = next(iter(cost.items()))
        print(f"| {backend} | {spent / len(seeds):.2f} s CPU per oracle episode |")
        return
    fast, vector = (cost[b] / len(seeds) for b in cost)
    print("| backend | CPU s per oracle episode | ratio |")
    print("|---|---|---|")
    print(f"| fast | {fast:.1f} | 1.00 |")
    print(f"| vector | {vector:.1f} | {fast / vector:.2f}x cheaper |")


if __name__ == "__main__":
    main()
