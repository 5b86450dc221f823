"""How fast can any decision policy drive on this stack? A perfect-information rollout planner.

    .venv/bin/python benchmarks/decision_ceiling.py [--episodes 20] [--horizon 15] [--base mobil]
                                                    [--jobs 2] [--config configs/highway.yaml]

At every decision point the planner copies the whole closed loop (the simulator is deterministic
once spawned, so the copy foresees the other vehicles exactly), tries each command the safety layer
lets through, follows it with the `--base` agent for `--horizon` seconds and keeps the command that
gets furthest down the road without a crash (a lane change must gain `LANE_CHANGE_MARGIN_M` more
than STAY). This is Bertsekas' rollout of the
base policy: it drives at least about as well as the base, with knowledge no real planner has, so
its mean speed is a practical ceiling for the decision layer on the same seeds (0..N-1) and
controllers. It is slow (three look-ahead rollouts per decision).
"""

from __future__ import annotations

import argparse
import copy
import json
import platform
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import numpy as np

from planner.factory import make_agent
from records import Command
from stack.core.closed_loop import ClosedLoop, grid_config
from stack.core.config import RunConfig, load_config
from stack.core.episodes import agent_step
from stack.sim.highway import HighwayAdapter

COMMANDS = (Command.STAY, Command.LEFT, Command.RIGHT)
LANE_CHANGE_MARGIN_M = 1.0
"""Progress a lane change must add over STAY to be chosen, m (no change for a rounding gain)."""


def progress_after(loop: ClosedLoop, command: Command, base, horizon_s: float) -> float:
    """Metres the ego gains in `horizon_s` after `command` then the base agent; -inf on a crash or
    when the safety layer masks `command` (it would only mean STAY)."""
    future = copy.deepcopy(loop)
    start_s, start_t, masked = future.world.s[0], future.world.time, future.safety.masked
    future.act(command)
    if future.safety.masked != masked:
        return -np.inf
    while not future.done and future.world.time - start_t < horizon_s:
        agent_step(future, base)
    return -np.inf if future.crashed else float(future.world.s[0] - start_s)


def episode(config: RunConfig, seed: int, base_name: str, horizon_s: float) -> dict:
    base = make_agent(base_name, config.highway.lanes_count, grid_config(config), seed)
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter, grid=getattr(base, "grid_config", None))
        loop.reset(seed)
        while not loop.done:
            loop.perceive()
            gains = [progress_after(loop, command, base, horizon_s) for command in COMMANDS]
            gains[1:] = [gain - LANE_CHANGE_MARGIN_M for gain in gains[1:]]

            loop.act(COMMANDS[int(np.argmax(gains))])
        result = loop.result(seed)
    return {
        "seed": seed,
        "mean_speed": result.mean_speed,
        "crashed": result.crashed,
        "lane_changes": result.lane_changes,
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--config", default="configs/highway.yaml")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--horizon", type=float, default=15.0, help="look-ahead per command, s")
    parser.add_argument("--base", default="mobil", help="agent followed after the first command")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    config = load_config(args.config)
    seeds = range(args.episodes)
    with ProcessPoolExecutor(args.jobs, mp_context=get_context("spawn")) as pool:
        rows = list(
            pool.map(
                episode, [config] * len(seeds), seeds, [args.base] * len(seeds), [args.horizon] * len(seeds)
            )
        )
    for row in rows:
        print(json.dumps(row))
    speeds = [row["mean_speed"] for row in rows]
    print(
        f"rollout of {args.base}, horizon {args.horizon:g} s, {len(rows)} episodes "
        f"({platform.processor() or platform.machine()}): mean speed {np.mean(speeds):.2f} m/s, "
        f"collisions {sum(row['crashed'] for row in rows)}, "
        f"lane changes/ep {np.mean([row['lane_changes'] for row in rows]):.2f}"
    )


if __name__ == "__main__":
    main()
