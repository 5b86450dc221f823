"""Record once, analyse offline (issue #71): drive the ensemble ungated over the uncertainty gate's
probes and the worlds it trained on, and keep, per decision, what any disagreement measure needs
and what happened next, so that measures are compared without driving again
(`benchmarks/gate_measures.py`).

    PYTHONPATH=. .venv/bin/python benchmarks/gate_record.py --episodes 20 --seed 1030000 \\
        [--training-episodes 10] [--probes "7 lanes,mixed drivers"] [--out runs/gate-record]

One `.npz` a world (`PROBES` of `benchmarks/uncertainty_gate.py`, and each world of the training
mix), episode k with seed `--seed` + k, one world at a time (`ClosedLoop`). Per decision:
`member_q` (members, 3) each member's Q-values, `rated` (3) the ensemble's with the MOBIL prior's
bonus, `chosen`, `permitted` (3, the safety layer's mask), `lookahead` (the lookahead's command on
the same reading), `speed` [m/s], `episode`; and within `--horizon` seconds after it: `ttc` (the
time below the 1.5 s TTC floor grew), `braking` (emergency brakings, by cause: columns in the order
of `stack.fault.emergency_causes.CAUSES`), `crashed`.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from uncertainty_gate import PROBES, probe_config  # noqa: E402

from planner.agents import decide  # noqa: E402
from planner.factory import SHIPPED_MODELS, make_agent  # noqa: E402
from planner.learned import LearnedAgent, load_agent  # noqa: E402
from records import Command, child_seed  # noqa: E402
from stack.apps.options import TRAIN_CONFIG  # noqa: E402
from stack.loop.closed_loop import ClosedLoop  # noqa: E402
from stack.runs.kept import kept_adapter, lookahead_setup  # noqa: E402
from stack.settings.run import RunConfig, grid_config, load_config, training_worlds  # noqa: E402


def badness(loop: ClosedLoop) -> np.ndarray:
    """What grows when something bad happens: time below the TTC floor [s], emergency brakings by
    cause, a collision."""
    return np.array(
        [float(loop.monitor.kept.time_below_ttc_floor_s[0]), *loop.causes.counts, float(loop.crashed)]
    )


def record_world(
    config: RunConfig, learned: LearnedAgent, episodes: int, seed: int, horizon: float
) -> dict[str, Any]:
    """Every decision of `episodes` ungated episodes of `config` (seeds `seed`...)."""
    fallback = make_agent(
        "lookahead", config.highway.lanes_count, grid_config(config), lookahead=lookahead_setup(config)
    )
    kept: dict[str, list[object]] = {
        name: []
        for name in ("member_q", "rated", "chosen", "permitted", "lookahead", "speed", "episode", "after")
    }
    for episode in range(episodes):
        loop = ClosedLoop(config, kept_adapter(config), grid=learned.grid_config)
        loop.reset(child_seed(seed, episode))
        starts: list[tuple[float, np.ndarray]] = []
        marks: list[tuple[float, np.ndarray]] = []
        while not loop.done:
            starts.append((loop.world.time, badness(loop)))
            observation = loop.observation(loop.perceive(), learned.encoding, learned.sees_permitted)
            actions, member_q = learned.choose_with_members(observation)
            chosen = int(np.asarray(actions).reshape(-1)[0])
            view = loop.perceive_as(fallback.grid_config).encode(fallback.encoding)
            kept["lookahead"].append(int(decide(fallback, view)))
            kept["member_q"].append(member_q[:, 0, :])
            kept["rated"].append(learned.last_rated[1][0])
            kept["chosen"].append(chosen)
            kept["permitted"].append(loop.permitted())
            kept["speed"].append(float(loop.world.speed[0]))
            kept["episode"].append(episode)
            loop.act(Command(chosen))
            marks.append((loop.world.time, badness(loop)))
        for start, before in starts:
            after = next((bad for end, bad in marks if end >= start + horizon), marks[-1][1])
            kept["after"].append(after - before)
    after = np.array(kept.pop("after"))
    arrays: dict[str, Any] = {name: np.array(values) for name, values in kept.items()}
    arrays["ttc"] = after[:, 0] > 0
    arrays["braking"] = after[:, 1:-1].astype(np.int64)
    arrays["crashed"] = after[:, -1] > 0
    return arrays


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--model", type=Path, default=None, help="an ensemble (default: the shipped ddqn)")
    parser.add_argument("--episodes", type=int, default=20, help="episodes a probe")
    parser.add_argument("--training-episodes", type=int, default=10, help="episodes a training world")
    parser.add_argument("--seed", type=int, default=1030000)
    parser.add_argument("--horizon", type=float, default=3.0, help="[s] an outcome counts this long after")
    parser.add_argument("--probes", default=",".join(PROBES))
    parser.add_argument("--out", type=Path, default=Path("runs/gate-record"))
    args = parser.parse_args()
    model = args.model or SHIPPED_MODELS["ddqn"]
    learned = load_agent(model, expected_algorithms=("ddqn", "dqn"))
    assert isinstance(learned, LearnedAgent)
    args.out.mkdir(parents=True, exist_ok=True)
    worlds: dict[str, tuple[RunConfig, int]] = {}
    for name in filter(None, args.probes.split(",")):
        scenario, overrides = PROBES[name]
        worlds[f"probe {name}"] = (probe_config(scenario, overrides, model), args.episodes)
    if args.training_episodes:
        for name, world in training_worlds(load_config(TRAIN_CONFIG)).items():
            worlds[f"train {name}"] = (world, args.training_episodes)
    for name, (config, episodes) in worlds.items():
        started = time.perf_counter()
        arrays = record_world(config, learned, episodes, args.seed, args.horizon)
        np.savez_compressed(args.out / f"{re.sub('[^A-Za-z0-9-]+', '_', name)}.npz", **arrays)
        print(f"{name}: {arrays['chosen'].size} decisions, {time.perf_counter() - started:.0f} s", flush=True)


if __name__ == "__main__":
    main()
