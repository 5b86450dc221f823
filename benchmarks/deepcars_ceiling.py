"""The highest DeepCars train accuracy an epsilon-greedy learner can reach, computed exactly.

    .venv/bin/python benchmarks/deepcars_ceiling.py [--epsilon 0.2] [--rows 1,2,3,4,5,6]
                                                    [--lanes 5] [--check-steps 1000000] [--best-only]

While training, a share `epsilon` of the actions is uniformly random, so even a perfect driver
collides now and then. Two limits, each as the accuracy passed / (passed + collided) x 100:
- the one-row lookahead rule (optimal without exploration: it never collides) acting
  epsilon-greedily, i.e. what a learner that found the noiseless optimum scores while exploring;
- the best of all policies acting epsilon-greedily (they may keep away from cars a random move
  could hit), by value iteration.

The chain is exact: the state is the ego lane and the lane of the one car in each of the `k`
rows ahead (or none, right after a reset); the car entering the top row is uniform and
independent of the past, so a policy that sees `k` rows is a Markov chain on that state. The value
is the expected number of cars passed from the reset state until the first collision, `N`;
accuracy = N / (N + 1) (renewal: one collision per episode; the 1000-step truncation, reached with
probability < 1e-7 at these collision rates, is ignored). The paper's 9-row line of sight is `k`
= 8 rows ahead; the table shows the limit settles long before (`--rows` up to 6 by default, ~1
min), and `--check-steps` simulates the lookahead rule in `DeepCarsBatch` as a check of the model
(95 % interval).
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from records import N_ACTIONS, Command
from stack.deepcars.rows import lookahead
from stack.deepcars.world import DeepCarsBatch


def behaviour(epsilon: float) -> np.ndarray:
    """(chosen, executed) probabilities: the chosen action, or with `epsilon` a uniform one."""
    return (1 - epsilon) * np.eye(N_ACTIONS) + epsilon / N_ACTIONS


def executed_values(values: np.ndarray, lanes: int) -> np.ndarray:
    """(executed action, ego, row 1 .. row k) -> cars passed until the first collision, from the
    values `V(ego, row 1 .. row k)` of the next step (the top row's new car is uniform)."""
    following = values.reshape(lanes, -1, lanes + 1)[:, :, :lanes].mean(axis=2)
    ego, car = np.arange(lanes)[:, None], np.arange(lanes + 1)[None, :]
    arrived = (car < lanes).astype(float)[:, :, None]
    result = []
    for action in Command:
        target = np.clip(ego + action.lane_shift, 0, lanes - 1)
        safe = (car != target).astype(float)[:, :, None]
        result.append((safe * (arrived + following[target[:, 0]][:, None, :])).reshape(values.shape))
    return np.stack(result)


def solve(lanes: int, rows: int, epsilon: float, policy: np.ndarray | None) -> float:
    """Accuracy [%] from the reset state: of `policy` (chosen action per state, shaped like the
    values) or, when None, of the best policy (value iteration)."""
    values = np.zeros((lanes,) + (lanes + 1,) * rows)
    mix = behaviour(epsilon)
    for _ in range(200_000):
        chosen = np.tensordot(mix, executed_values(values, lanes), axes=1)
        new = chosen.max(axis=0) if policy is None else np.take_along_axis(chosen, policy[None], 0)[0]
        converged = np.abs(new - values).max() < 1e-10
        values = new
        if converged:
            break
    start = values[(lanes // 2,) + (lanes,) * rows]
    return float(100 * start / (start + 1))


def lookahead_policy(lanes: int, rows: int) -> np.ndarray:
    """The one-row lookahead rule on every state (flattened as in `solve`)."""
    ego, car = np.meshgrid(np.arange(lanes), np.arange(lanes + 1), indexing="ij")
    distances = np.full((ego.size, lanes), rows + 1)
    hit = car.ravel() < lanes
    distances[np.flatnonzero(hit), car.ravel()[hit]] = 1
    actions = lookahead(np.concatenate([ego.ravel()[:, None], distances], axis=1)).reshape(lanes, -1)
    return np.repeat(actions[:, :, None], (lanes + 1) ** (rows - 1), axis=2).reshape(
        (lanes,) + (lanes + 1,) * rows
    )


def simulated(epsilon: float, lanes: int, steps: int, seed: int = 0) -> tuple[float, float]:
    """The lookahead rule acting epsilon-greedily in `DeepCarsBatch` (9 rows, up to 1000 envs of at
    least 200 steps): accuracy [%] and the half-width of its 95 % interval (collisions as a
    binomial share of the cars)."""
    envs = max(1, min(1000, steps // 200))
    batch = DeepCarsBatch(envs, lanes=lanes, encoding="tabular", seed=seed)
    rng = np.random.default_rng(seed + 1)
    observations = batch.observe()
    for _ in range(steps // batch.n):
        actions = lookahead(observations)
        explore = rng.random(batch.n) < epsilon
        actions[explore] = rng.integers(0, N_ACTIONS, int(explore.sum()))
        observations, *_ = batch.step(actions)
    cars = batch.passed + batch.collisions
    share = batch.collisions / cars
    return 100 * (1 - share), 100 * 1.96 * np.sqrt(share * (1 - share) / cars)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--epsilon", type=float, default=0.2)
    parser.add_argument("--lanes", type=int, default=5)
    parser.add_argument("--rows", default="1,2,3,4,5,6", help="rows ahead the policy sees, k")
    parser.add_argument("--check-steps", type=int, default=1_000_000, help="0: no simulation")
    parser.add_argument("--best-only", action="store_true", help="skip the rule (it reads row 1 only)")
    args = parser.parse_args()
    print(f"{platform.node()}, {platform.processor() or platform.machine()}; epsilon {args.epsilon}")
    print(
        "| rows ahead seen (line of sight - 1) | lookahead rule, epsilon-greedy | best policy, "
        "epsilon-greedy | s |"
    )
    print("|---|---|---|---|")
    for rows in (int(value) for value in args.rows.split(",")):
        start = time.perf_counter()
        rule = (
            None
            if args.best_only
            else solve(args.lanes, rows, args.epsilon, lookahead_policy(args.lanes, rows))
        )
        best = solve(args.lanes, rows, args.epsilon, None)
        shown = "-" if rule is None else f"{rule:.3f} %"
        print(f"| {rows} | {shown} | {best:.3f} % | {time.perf_counter() - start:.1f} |")
    if args.check_steps:
        accuracy, half = simulated(args.epsilon, args.lanes, args.check_steps)
        print(f"simulated lookahead rule, {args.check_steps} steps: {accuracy:.3f} % +- {half:.3f}")


if __name__ == "__main__":
    main()
