"""Real-time validation of the shipped training config, one world at a time against batched worlds:
the CPU seconds of each and whether the scores are the same, bit for bit, with a trained model
deciding (by default the shipped ddqn, the mean of its three networks).

    .venv/bin/python benchmarks/batched_validation.py [--episodes 40] [--seed 100000] [--model M]

Episode k of a validation is drawn from child_seed(seed, k), as the training run's validations draw
theirs (`train.validation.seed`: 100000 in the shipped config).
"""

from __future__ import annotations

import argparse
import time

from planner.factory import model_path
from planner.learned import load_agent
from planner.validation import validate
from stack.settings.run import load_config
from stack.training.batch_validation import BatchedValidation
from stack.training.decision_env import HierarchicalHighwayEnv


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--config", default="configs/train/ddqn.yaml")
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--seed", type=int, default=100_000)
    parser.add_argument("--model", default=None, help="a model file (default: the shipped ddqn)")
    args = parser.parse_args()
    config = load_config(args.config)
    agent = load_agent(model_path("ddqn", args.model))  # type: ignore[arg-type]
    batched = BatchedValidation.of(config)
    assert batched is not None, "the config's worlds run in batches"
    env = HierarchicalHighwayEnv(config)
    batched.measure(agent.predict, 2, args.seed + 1)  # compiled and warm before it is timed
    validate(agent.predict, env, 1, args.seed + 1)
    cpu = time.process_time()
    one_at_a_time = validate(agent.predict, env, args.episodes, args.seed)
    per_world = time.process_time() - cpu
    cpu = time.process_time()
    together = batched.measure(agent.predict, args.episodes, args.seed)
    in_batches = time.process_time() - cpu
    print(f"{args.episodes} validation episodes from seed {args.seed}:")
    ratio = per_world / in_batches
    print(f"one world at a time {per_world:.1f} CPU-s, batched {in_batches:.1f} CPU-s: {ratio:.1f}x")
    print(f"the same score bit for bit: {together == one_at_a_time}")
    print(f"collision rate {together.collision_rate:.3f}, mean return {together.mean_return!r}")


if __name__ == "__main__":
    main()
