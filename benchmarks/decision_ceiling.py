"""How fast can any decision policy drive on this stack? The `oracle` agent as a one-decision rollout.

    .venv/bin/python benchmarks/decision_ceiling.py [--episodes 20] [--horizon 15] [--base mobil]
                                                    [--depth 1] [--jobs 2] [--config configs/highway.yaml]

The oracle (`stack.agents.oracle`) copies the whole closed loop at every decision point (the simulator
is deterministic once spawned, so the copy foresees the other vehicles exactly), tries each command
the safety layer lets through (with `--depth 2`, each pair of consecutive commands), follows it with
the `--base` agent for `--horizon` seconds and keeps the command that gets furthest down the road
without a crash. With depth 1 and a MOBIL base this is Bertsekas' rollout of MOBIL: it drives at
least about as well as the base, with knowledge no real planner has, so its mean speed is a
practical ceiling for the decision layer on the same seeds (0..N-1) and controllers. The same runs
as `drivestack compare --agents oracle` with these `planner.oracle` settings.
"""

from __future__ import annotations

import argparse
import json
import platform

import numpy as np

from stack.runs.episodes import run
from stack.settings.run import load_config


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--config", default="configs/highway.yaml")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--horizon", type=float, default=15.0, help="look-ahead per command, s")
    parser.add_argument("--base", default="mobil", help="agent followed after the searched commands")
    parser.add_argument("--depth", type=int, default=1, help="consecutive decisions searched")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    oracle = {"depth": args.depth, "horizon_s": args.horizon, "base": args.base}
    config = load_config(args.config, planner__agent="oracle", planner__oracle=oracle, episodes=args.episodes)
    results = run(config, progress=True, jobs=args.jobs)
    for episode in results.episodes:
        print(
            json.dumps({"seed": episode.seed, **{k: getattr(episode, k) for k in ("mean_speed", "crashed")}})
        )
    print(
        f"oracle (depth {args.depth}, {args.base} base, horizon {args.horizon:g} s), {len(results.episodes)} "
        f"episodes ({platform.processor() or platform.machine()}): mean speed "
        f"{np.mean([e.mean_speed for e in results.episodes]):.2f} m/s, collisions "
        f"{results.summary['collisions']}, lane changes/ep {results.summary['lane_changes']:.2f}"
    )


if __name__ == "__main__":
    main()
