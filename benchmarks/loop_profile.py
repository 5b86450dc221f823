"""Where a closed-loop frame's CPU time goes, by component: the simulation (the vector road's act and
step), the env's own step around it, the world snapshot, the controllers, the maneuver, the safety
monitor and the metrics, perception and decisions, and the episode's start-up.

    .venv/bin/python benchmarks/loop_profile.py [--scenario highway-v0] [--agent mobil] [--episodes 3]

CPU time (process time) of `run_episode` over seeded episodes (`--duration` s each, one warm-up
episode first), each component timed by a wrapper around its entry point (the wrappers add about a
microsecond per call; nested components are listed under their parent, and "rest" is what no listed
component covers). Runs on any revision of the stack that has these entry points, so the same
script profiles the code before and after a change (before issue 34 the tick itself fed the
metrics recorder and the safety monitor: there they are part of "tick", not beside it).
"""

from __future__ import annotations

import argparse
import collections
import functools
import platform
import time
from collections.abc import Callable
from typing import Any

COMPONENTS = [
    line.split(" = ")
    for line in """\
act (control ticks to the next decision) = stack.loop.closed_loop:ClosedLoop.act
  tick = stack.loop.closed_loop:ClosedLoop.tick
    env step (adapter) = stack.sim.highway:HighwayAdapter.step
      road act (traffic decisions, IDM) = stack.sim.vector.road:VectorRoad.act
      road step (kinematics, collisions) = stack.sim.vector.road:VectorRoad.step
      world snapshot = stack.sim.highway:snapshot
    controller = controllers.tracker:SteeringTracker.step
    maneuver reference = controllers.maneuver:Maneuver.reference
    emergency braking = controllers.emergency:EmergencyBraking.apply
  metrics recorder = stack.loop.metrics:EpisodeRecorder.record
  safety monitor = stack.loop.safety_metrics:SafetyMonitor.record
perception (grid) = stack.loop.closed_loop:ClosedLoop.perceive
start-up: env reset = stack.loop.closed_loop:ClosedLoop.reset""".splitlines()
]
"""(label, module:[Owner.]attribute): indentation nests a component in the one above."""


def instrument(
    spent: collections.Counter[str],
    components: list[list[str]] = COMPONENTS,
    clock: Callable[[], int] = time.process_time_ns,
) -> None:
    """Wrap every component's entry point (label, module:[Owner.]attribute) so that the time
    `clock` [ns] measures in it (CPU time by default) adds up in `spent`; one missing from this
    revision of the stack is skipped."""
    import importlib

    for label, where in components:
        module_name, path = where.split(":")
        owner_name, _, attribute = path.rpartition(".")
        module = importlib.import_module(module_name)
        owner: Any = getattr(module, owner_name) if owner_name else module
        original = getattr(owner, attribute, None)
        if original is None:
            continue

        def timed(*args: Any, _original: Callable = original, _label: str = label, **kwargs: Any) -> Any:
            start = clock()
            try:
                return _original(*args, **kwargs)
            finally:
                spent[_label] += clock() - start

        setattr(owner, attribute, functools.wraps(original)(timed))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenario", default="highway-v0")
    parser.add_argument("--agent", default="mobil")
    parser.add_argument("--backend", default="vector")
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--duration", type=float, default=15.0, help="episode length [s]")
    args = parser.parse_args()
    from stack.runs.episodes import run_episode
    from stack.settings.run import build_config

    config = build_config(
        {"planner": {"agent": args.agent}, "sim": {"backend": args.backend}, "seed": 0},
        scenario=args.scenario,
        highway__duration=args.duration,
    )
    spent: collections.Counter[str] = collections.Counter()
    instrument(spent)
    run_episode(config, args.episodes)
    spent.clear()
    start = time.process_time_ns()
    frames = sum(run_episode(config, episode).steps for episode in range(args.episodes))
    total = time.process_time_ns() - start
    print(
        f"{platform.machine()}, Python {platform.python_version()}; {args.scenario}, {args.agent}, "
        f"{args.backend}: {args.episodes} x {args.duration:g} s, {frames} frames"
    )
    print("| component | us per frame | share |\n|---|---|---|")
    print(f"| whole episode | {total / 1e3 / frames:.0f} | 100 % |")
    for label, *_ in COMPONENTS:
        if label in spent:
            print(
                f"| {label.replace(' ', '&nbsp;', label.count(' ') - label.lstrip().count(' '))} | "
                f"{spent[label] / 1e3 / frames:.0f} | {100 * spent[label] / total:.0f} % |"
            )
    covered = spent[COMPONENTS[0][0]] + spent["perception (grid)"] + spent["start-up: env reset"]
    print(
        f"| rest (decisions, env make, results) | {(total - covered) / 1e3 / frames:.0f} | "
        f"{100 * (total - covered) / total:.0f} % |"
    )


if __name__ == "__main__":
    main()
