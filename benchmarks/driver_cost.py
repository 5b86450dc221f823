"""What a driver population costs per frame against highway-env's own drivers, in one sitting: the
`vector` backend driving one world alone (frames per CPU-second, `HighwayAdapter.step`, snapshot
included) and a batch of worlds (`TrafficBatch.step`, world-frames per CPU-second), on the same
worlds (seeds 0, 1, ...) with the same braking ego as `batched_traffic.py`, which shows the traffic
lane `--intent` (default 1) as the lane it changes into the whole time: the yielding drivers'
worst case (every cautious driver behind the ego in that lane evaluates IDM behind it each frame).

    .venv/bin/python benchmarks/driver_cost.py [--scenario highway-v0] [--runs 3] [--frames 150]
        [--intent 1] [--populations highway-env,calibrated,...]
    .venv/bin/python benchmarks/driver_cost.py --closed-loop [--agent mobil] [--episodes 4]
        [--scenario highway-v0] [--runs 3] [--populations ...]
    .venv/bin/python benchmarks/driver_cost.py --draws [--runs 3] [--populations ...]

With `--draws`: what drawing one driver at spawn costs (`assign_drivers`, as a reset draws them;
wall-clock microseconds, the median of `--runs` runs of 2,000 drivers): a population's
per-episode cost, which a batch of short episodes pays every reset.

With `--closed-loop`: what a run costs a frame, the whole stack with its traffic (perception,
`--agent`, control, metrics, the fault judge), per world (`run_episode` over `--episodes` seeded
episodes, one world at a time) and in a batch (`run_batched` of `BATCH_WORLDS` episodes), frames
per CPU-second; the episodes differ between populations (their drivers do), so each is its own
frames over its own CPU time.

The populations alternate run by run, after one warm-up run each; the figures are medians. A
population changes the traffic too (aggressive drivers change lane more often), so its cost is
its per-driver parameters and the traffic it makes together.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import statistics
import time

import numpy as np
from batched_traffic import batch_rate, vector_rate

from stack.runs.alone import run_episode
from stack.runs.batch_episodes import run_batched
from stack.settings.run import RunConfig, build_config
from stack.sim.drivers import assign_drivers
from stack.worlds import drivers

SAME_AS_HIGHWAY_ENV = "highway-env-drawn"
"""A population that draws highway-env's own values (jam clearance 5 m beyond the length, no speed
factor): the same traffic, bit for bit, with every parameter read per driver: the cost of the
per-driver parameters alone."""
drivers.POPULATION_RANGES[SAME_AS_HIGHWAY_ENV] = drivers.DriverRanges(
    desired_speed_factor=(1.0, 1.0),
    time_gap_s=(1.5, 1.5),
    max_acceleration=(3.0, 3.0),
    comfortable_deceleration=(5.0, 5.0),
    jam_clearance_m=(5.0, 5.0),
    politeness=(0.0, 0.0),
    threshold=(0.2, 0.2),
    safe_braking=(2.0, 2.0),
    decision_period_s=(1.0, 1.0),
)
drivers.POPULATIONS = (*drivers.POPULATIONS, SAME_AS_HIGHWAY_ENV)
POPULATIONS = (
    "highway-env",
    SAME_AS_HIGHWAY_ENV,
    "calibrated",
    "aggressive",
    "cautious",
    "distracted",
    "blind",
    "mixed",
)
BATCH_WORLDS = 64


def draw_cost(name: str, drivers: int = 2000) -> float:
    """Wall-clock microseconds to draw and set one driver of `name`, as a reset does it
    (`assign_drivers` over `drivers` vehicles)."""

    class Vehicle:
        target_speed, LENGTH = 25.0, 5.0

    vehicles = [Vehicle() for _ in range(drivers)]
    start = time.perf_counter()
    assign_drivers(vehicles, name, np.random.default_rng(0), (Vehicle,), 15.0)
    return 1e6 * (time.perf_counter() - start) / drivers


def closed_loop_rates(config: RunConfig, episodes: int) -> tuple[float, float]:
    """(per world, batch) closed-loop frames per CPU-second of `config`'s first episodes: `episodes`
    run one at a time, `BATCH_WORLDS` stepped as one batch."""
    start = time.process_time()
    alone = sum(run_episode(config, episode).steps for episode in range(episodes))
    alone_rate = alone / (time.process_time() - start)
    start = time.process_time()
    together = sum(result.steps for result in run_batched(config, range(BATCH_WORLDS)))
    return alone_rate, together / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenario", default="highway-v0")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--intent", type=int, default=1, help="the lane the ego shows it changes into")
    parser.add_argument("--populations", default=",".join(POPULATIONS), help="comma-separated")
    parser.add_argument("--closed-loop", action="store_true", help="the whole stack's frames")
    parser.add_argument("--draws", action="store_true", help="the cost of drawing one driver")
    parser.add_argument("--agent", default="mobil", help="with --closed-loop: the agent deciding")
    parser.add_argument("--episodes", type=int, default=4, help="with --closed-loop: episodes run alone")
    args = parser.parse_args()
    populations = args.populations.split(",")
    if args.draws:
        print(f"{datetime.date.today()} {platform.processor() or platform.machine()}, us a driver drawn")
        for name in (name for name in populations if name != "highway-env"):
            print(f"| {name} | {statistics.median(draw_cost(name) for _ in range(args.runs)):.1f} |")
        return
    if populations[0] != "highway-env":
        populations.insert(0, "highway-env")
    alone: dict[str, list[float]] = {name: [] for name in populations}
    batched: dict[str, list[float]] = {name: [] for name in populations}
    if args.closed_loop:
        configs = {
            name: build_config({}, scenario=args.scenario, traffic=name, planner__agent=args.agent, seed=0)
            for name in populations
        }
        for config in configs.values():
            run_episode(config, 0)
        for _ in range(args.runs):
            for name, config in configs.items():
                per_world, batch_of = closed_loop_rates(config, args.episodes)
                alone[name].append(per_world)
                batched[name].append(batch_of)
        what = f"closed loop, {args.agent}, {args.episodes} episodes alone"
    else:
        highways = {
            name: build_config({}, scenario=args.scenario, traffic=name).highway for name in populations
        }
        for highway in highways.values():
            vector_rate(highway, 0, 10, args.intent), batch_rate(highway, 4, 10, args.intent)
        for _ in range(args.runs):
            for name, highway in highways.items():
                alone[name].append(
                    statistics.mean(vector_rate(highway, w, args.frames, args.intent) for w in range(3))
                )
                batched[name].append(batch_rate(highway, BATCH_WORLDS, args.frames, args.intent))
        what = f"traffic alone, intent lane {args.intent}"
    machine = platform.processor() or platform.machine()
    print(f"{datetime.date.today()} {machine}, {args.scenario}, {args.runs} runs, {what}")
    batch = f"batch of {BATCH_WORLDS} world-frames/CPU-s"
    print(f"| drivers | per world frames/CPU-s | vs highway-env | {batch} | vs highway-env |")
    print("|---|---|---|---|---|")
    base_alone, base_batched = (
        statistics.median(alone["highway-env"]),
        statistics.median(batched["highway-env"]),
    )
    for name in populations:
        a, b = statistics.median(alone[name]), statistics.median(batched[name])
        alone_cost, batched_cost = base_alone / a - 1, base_batched / b - 1
        print(f"| {name} | {a:.0f} | {alone_cost:+.1%} cost | {b:.0f} | {batched_cost:+.1%} cost |")


if __name__ == "__main__":
    main()
