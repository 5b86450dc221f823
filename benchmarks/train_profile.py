"""Where one member of the shipped training spends its CPU time: the demonstrations, pre-training,
the batched worlds' steps, the learner's gradient steps, validation episodes, checkpoints, start-up
and the rest (acting, SB3's rollouts and replay buffer), on a reduced run of
`configs/train/ddqn.yaml` in one process (`train.envs` 1, the same run as 2 shards), then scaled to
the full member and to the three-member training.

    .venv/bin/python benchmarks/train_profile.py [--steps 30000] [--demonstrations 128]
        [--pretrain 2000] [--validation-episodes 50] [--seed 1024000] [--one-world-validation]

Each part is timed exclusively (a part called inside another counts for itself only) in CPU
seconds of this process, so a machine shared with other runs barely moves the figures. The scaled
estimate multiplies each part's CPU per unit (an episode, a gradient step, a decision) by the
units of the full run: 900 demonstration episodes, 20,000 pre-training steps, 300,000 decisions,
18,750 gradient steps and `--full-validation-episodes` validation episodes (a member of the shipped
run validates 4 to 7 times on 100 episodes and 4 times on 20). With `--envs 2` the worlds step and
the demonstrations are recorded in worker processes, whose CPU this process does not see.
"""

from __future__ import annotations

import argparse
import collections
import functools
import importlib
import json
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from stack.settings.run import load_config
from stack.training.trainer import Trainer

PARTS = [
    ["demonstrations", "stack.training.demonstrations:collect_demonstrations"],
    ["pre-training", "planner.ddqn:DoubleDQN.pretrain"],
    ["validation episodes", "planner.validation:validate"],
    ["validation episodes", "stack.training.batch_validation:BatchedValidation.measure"],
    ["batched worlds' steps", "stack.training.batch_env:TrainingWorlds.step_wait"],
    ["gradient steps", "planner.ddqn:DoubleDQN._train"],
    ["checkpoints", "stack.training.trainer:Trainer._save_checkpoint"],
    ["start-up", "stack.training.trainer:Trainer.__init__"],
]
"""(label, module:[Owner.]attribute) whose CPU time is added up, exclusive of the parts inside."""


def instrument(spent: collections.Counter[str], calls: collections.Counter[str]) -> None:
    """Wrap every part's entry point so that the CPU time spent in it, less the time spent in
    parts it calls, adds up in `spent` [ns]; `calls` counts the calls."""
    inside: list[list[int]] = []

    for label, where in PARTS:
        module_name, path = where.split(":")
        owner_name, _, attribute = path.rpartition(".")
        module = importlib.import_module(module_name)
        owner: Any = getattr(module, owner_name) if owner_name else module
        original = getattr(owner, attribute)

        def timed(*args: Any, _original: Callable = original, _label: str = label, **kwargs: Any) -> Any:
            start, nested = time.process_time_ns(), [0]
            inside.append(nested)
            try:
                return _original(*args, **kwargs)
            finally:
                inside.pop()
                elapsed = time.process_time_ns() - start
                spent[_label] += elapsed - nested[0]
                calls[_label] += 1
                if inside:
                    inside[-1][0] += elapsed

        setattr(owner, attribute, functools.wraps(original)(timed))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--config", default="configs/train/ddqn.yaml")
    parser.add_argument("--steps", type=int, default=30_000)
    parser.add_argument("--demonstrations", type=int, default=128)
    parser.add_argument("--pretrain", type=int, default=2_000)
    parser.add_argument("--validation-episodes", type=int, default=50, help="of each long validation")
    parser.add_argument("--full-validation-episodes", type=int, default=580)
    parser.add_argument("--seed", type=int, default=1_024_000)
    parser.add_argument("--envs", type=int, default=1)
    parser.add_argument(
        "--one-world-validation", action="store_true", help="validate one world at a time, as before"
    )
    args = parser.parse_args()
    if args.one_world_validation:
        from stack.training.batch_validation import BatchedValidation

        BatchedValidation.of = classmethod(lambda cls, config: None)  # type: ignore[method-assign,assignment]
    spent: collections.Counter[str] = collections.Counter()
    calls: collections.Counter[str] = collections.Counter()
    instrument(spent, calls)
    config = load_config(
        args.config,
        seed=args.seed,
        train__members=1,
        train__envs=args.envs,
        train__steps=args.steps,
        train__checkpoint_every=args.steps,
        train__demonstrations__episodes=args.demonstrations,
        train__demonstrations__pretrain_steps=args.pretrain,
        train__validation__short_every=args.steps // 3,
        train__validation__long_every=args.steps,
        train__validation__long_episodes=args.validation_episodes,
    )
    with tempfile.TemporaryDirectory() as out:
        cpu, wall = time.process_time(), time.perf_counter()
        trainer = Trainer(config, Path(out), progress=False)
        trainer.run()
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        history = json.loads((Path(out) / "validation.json").read_text())
    episodes = sum(validation["episodes"] for validation in history)
    seconds = {label: ns / 1e9 for label, ns in spent.items()}
    seconds["rest"] = cpu - sum(seconds.values())
    decisions = args.steps
    gradient_steps = calls["gradient steps"] and round(decisions * config.train.replay_ratio)
    units = {
        "demonstrations": (args.demonstrations, 900, "episode"),
        "pre-training": (args.pretrain, 20_000, "gradient step"),
        "validation episodes": (episodes, args.full_validation_episodes, "episode"),
        "batched worlds' steps": (decisions, 300_000, "decision"),
        "gradient steps": (gradient_steps, 18_750, "gradient step"),
        "rest": (decisions, 300_000, "decision"),
    }
    print(
        f"reduced run: {cpu:.1f} CPU-s in {wall:.1f} s wall; seed {args.seed}, {episodes} validation episodes"
    )
    print("\n| part | CPU s (reduced run) | units | CPU ms a unit | full member (est. CPU s) |")
    print("|---|---|---|---|---|")
    total = 0.0
    for label, value in seconds.items():
        done, full, unit = units.get(label, (1, 1, "run"))
        per = value / done if done else 0.0
        estimate = per * full
        total += estimate
        print(f"| {label} | {value:.1f} | {done} {unit}s | {1e3 * per:.2f} | {estimate:.0f} |")
    print(f"| **total** | {cpu:.1f} | | | **{total:.0f}** |")


if __name__ == "__main__":
    main()
