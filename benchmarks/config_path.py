"""The path a training config takes through the code: which project modules run, and how often the
running code climbs back up a floor of the import order, while a training config is resolved.

What is traced: `load_config(configs/train/ddqn.yaml)` (read the YAML, apply its scenario, validate
the run config and its `train:` section) and then the worlds of its scenario mix as the decision
MDP builds them (one resolved run config per scenario). Every call and return of a function in a
project module is followed (`sys.setprofile`); the running module is that of the innermost project
frame. Reported: the modules crossed (distinct modules that ran), the changes of running module,
and the climbs: changes to a module on a higher floor of the import order (docs/architecture.md:
records and common lowest, then the layers, then the floors of `stack`), i.e. code that went down
to a lower floor and came back up. A config that is resolved in one place, below the code reading
it, climbs once per call it makes into the layers beneath (validators asking `planner` or
`perception`), and between floors of `stack` only back from the readers of its data (`READERS`):
each scenario's file once, the config's YAML once.

    python benchmarks/config_path.py [--config configs/train/ddqn.yaml]

Before `stack/core` was split (issue #51; measured with this script's imports pointed at
`stack.core.config` and the floors sim < core < training < apps) the shipped ddqn.yaml (a mix of 9
scenarios) crossed the same 12 modules with 2,286 changes of running module and 1,102 climbs, 705
of them between floors of `stack` (config <-> scenarios and the road settings, back and forth), and
resolved its scenarios 100 times (each road 10 times); BENCHMARKS.md has the figures after.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from itertools import pairwise
from pathlib import Path
from types import FrameType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
GROUND = ("records", "common")
LAYERS = ("perception", "planner", "controllers")
STACK_FLOORS = (
    *("runtime", "worlds", "settings", "sim", "rrd", "results", "fault", "loop"),
    *("batch", "agents", "runs", "assessment", "training", "apps"),
)
"""`stack`'s floors, lowest first (docs/architecture.md)."""
READERS = ("stack.worlds.scenarios", "stack.runtime.yaml_text")
"""The modules below `settings` it reads data through: the scenario files (each scenario once, its
`apply` and its `road`) and the config's YAML; a return from them is the one expected climb."""


def floor_of(module: str) -> int | None:
    """The floor of the import order `module` stands on, or None outside the project."""
    top, _, rest = module.partition(".")
    if top in GROUND:
        return 0
    if top in LAYERS:
        return 1
    if top == "stack":
        part = rest.split(".")[0]
        return 2 + STACK_FLOORS.index(part) if part in STACK_FLOORS else None
    return None


def traced(work: Any) -> tuple[list[str], Counter[str]]:
    """The running project module after each change, while `work()` runs, and how often each
    scenario was resolved (`scenarios.apply`: a run config moved to it; `scenarios.road`: its road)."""
    running: list[str] = []
    inner: list[str] = []
    resolved: Counter[str] = Counter()

    def profile(frame: FrameType, event: str, arg: object) -> None:
        if event not in ("call", "return"):
            return
        module = frame.f_globals.get("__name__", "")
        if floor_of(module) is None:
            return
        if event == "call":
            inner.append(module)
            if module.endswith(".scenarios") and frame.f_code.co_name in ("apply", "road"):
                resolved[f"{frame.f_code.co_name}({frame.f_locals.get('name')})"] += 1
        elif inner:
            inner.pop()
        now = inner[-1] if inner else ""
        if now and (not running or running[-1] != now):
            running.append(now)

    sys.setprofile(profile)
    try:
        work()
    finally:
        sys.setprofile(None)
    return running, resolved


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "configs" / "train" / "ddqn.yaml"))
    args = parser.parse_args()
    from stack.settings.run import load_config, scenario_road, training_worlds

    def work() -> None:
        training_worlds(load_config(args.config))

    work()  # imports first, so only the path itself is traced
    scenario_road.cache_clear()  # its roads resolved afresh, as in a new process
    running, resolved = traced(work)
    climbs = [(a, b) for a, b in pairwise(running) if (floor_of(b) or 0) > (floor_of(a) or 0)]
    in_stack = [(a, b) for a, b in climbs if a.startswith("stack.") and b.startswith("stack.")]
    beyond_readers = [(a, b) for a, b in in_stack if a not in READERS]
    print(f"modules crossed: {len(set(running))} ({', '.join(sorted(set(running)))})")
    print(f"changes of running module: {len(running) - 1}")
    print(
        f"climbs back up a floor: {len(climbs)}, of them between floors of stack: {len(in_stack)} "
        f"(beyond the readers of the scenarios and the YAML: {len(beyond_readers)})"
    )
    each = ", ".join(f"{call} x{count}" for call, count in sorted(resolved.items()))
    print(f"scenario resolutions: {sum(resolved.values())} ({each})")
    for (a, b), count in Counter(climbs).most_common():
        print(f"  {count:5d}  {a} -> {b}")


if __name__ == "__main__":
    main()
