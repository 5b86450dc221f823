"""The per-world closed loop on the `vector` backend against the same loop on a prototype plant that
steps the batch's traffic kernels with one world (`TrafficBatch(highway, 1)`): CPU ms per frame of
the same seeded episodes, the two plants alternating episode by episode (so machine load hits
them alike), and whether the episodes are the same.

    .venv/bin/python benchmarks/batch_of_one.py [--episodes 3] [--repeats 3] [--seed 1013000]
        [--scenario highway-v0] [--agent mobil] [--duration 15]

The prototype plant (`BatchOfOne`) is what "the per-world road as the batch of one world" would
be: `TrafficBatch.step` of one world, then the world the loop reads. The batch's state of record is
its arrays; the loop reads a `WorldState`, and today the only way from the arrays to one is
through highway-env's objects (`TrafficBatch.road`, then `stack.sim.highway.snapshot`: what
`ClosedLoopBatch.world_state` does), so the prototype pays that on every frame; `--traffic-only`
times the traffic steps alone (no loop, no snapshot) as the floor any such plant stands on.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np

from records import Actuation, WorldState
from stack.results.episode_result import TIMING_FIELDS
from stack.runs.alone import run_agent_episode
from stack.runs.kept import kept_agent
from stack.settings.run import RunConfig, build_config
from stack.settings.world import HighwayConfig
from stack.sim.batch.traffic import TrafficBatch
from stack.sim.batch.world_reading import world_state_of_rows
from stack.sim.highway import HighwayAdapter, snapshot


class BatchOfOne:
    """A `Plant` over the batch's traffic with one world (module docstring)."""

    def __init__(self, highway: HighwayConfig, through_objects: bool = False) -> None:
        self.through_objects = through_objects
        self.batch = TrafficBatch(highway, 1)
        self.dt = self.batch.dt
        self.lanes = highway.lanes_count
        self.terminated = self.truncated = False
        self.rendering = False
        self.only = np.ones(1, dtype=bool)

    def reset(self, seed: int) -> WorldState:
        self.batch.reset([seed])
        self.terminated = self.truncated = False
        return self.world()

    def step(self, actuation: Actuation) -> WorldState:
        ended = self.batch.step([actuation.acceleration], [actuation.steering], only=self.only)
        self.terminated, self.truncated = bool(ended.terminated[0]), bool(ended.truncated[0])
        return self.world()

    def world(self) -> WorldState:
        if self.through_objects:
            _, ego = self.batch.road(0)
            return snapshot(ego.road, ego, float(self.batch.time[0]), self.lanes)
        return world_of_arrays(self.batch, self.lanes)

    def show_intent(self, lane: int) -> None:
        self.batch.arrays.intent[0] = lane

    @property
    def done(self) -> bool:
        return self.terminated or self.truncated

    def render(self) -> np.ndarray:
        raise NotImplementedError("the prototype does not render")

    def close(self) -> None:
        self.batch.close()


def world_of_arrays(batch: TrafficBatch, lanes_count: int) -> WorldState:
    """World 0 of `batch` as the loop reads it, straight from the arrays (`BatchArrays.world_batch`,
    compiled; `world_state_of_rows`), on a road of straight lanes (highway-v0's): what `snapshot`
    makes of the objects."""
    arrays = batch.arrays
    table = batch._lane_tables[0]
    assert table is not None
    ego = int(arrays.ego[0])
    return world_state_of_rows(
        arrays.world_batch(), 0, arrays.x, arrays.y, arrays.crashed, ego, float(arrays.steering[0, ego]),
        float(batch.time[0]), tuple(table.lanes[:lanes_count]),
    )  # fmt: skip


def episodes_cpu(config: RunConfig, plants: dict[str, object], seeds: list[int]) -> tuple[dict, int, bool]:
    """CPU seconds per plant over `seeds` (alternating), frames, and whether every episode agreed."""
    from stack.loop.closed_loop import ClosedLoop

    agent = kept_agent(config, seeds[0])
    cpu = dict.fromkeys(plants, 0.0)
    frames, same = 0, True
    for episode, seed in enumerate(seeds):
        rows = {}
        for name, plant in plants.items():
            start = time.process_time()
            loop = ClosedLoop(config, plant, grid=agent.grid_config)  # type: ignore[arg-type]
            result = run_agent_episode(loop, agent, episode, seed)
            cpu[name] += time.process_time() - start
            rows[name] = {k: v for k, v in result.row().items() if k not in TIMING_FIELDS}
        same = same and rows["vector"] == rows["batch of one"]
        frames += result.steps
    return cpu, frames, same


def traffic_only(highway: HighwayConfig, seeds: list[int], frames: int) -> dict[str, float]:
    """CPU ms per frame of the traffic steps alone: the vector adapter's step (its snapshot
    included: the loop needs one) and the batch of one's step (no world read back)."""
    adapter, batch = HighwayAdapter(highway, "vector"), TrafficBatch(highway, 1)
    braking = Actuation(acceleration=-2.0, steering=0.0)
    cpu = dict.fromkeys(
        (
            "vector step + snapshot",
            "batch of one step",
            "batch of one step + snapshot",
            "batch of one step + arrays' world",
        ),
        0.0,
    )
    only = np.ones(1, dtype=bool)
    for seed in seeds:
        adapter.reset(seed)
        start = time.process_time()
        for _ in range(frames):
            adapter.step(braking)
        cpu["vector step + snapshot"] += time.process_time() - start
        batch.reset([seed])
        start = time.process_time()
        for _ in range(frames):
            batch.step([-2.0], [0.0], only=only)
        cpu["batch of one step"] += time.process_time() - start
        batch.reset([seed])
        start = time.process_time()
        for _ in range(frames):
            batch.step([-2.0], [0.0], only=only)
            _, ego = batch.road(0)
            snapshot(ego.road, ego, float(batch.time[0]), highway.lanes_count)
        cpu["batch of one step + snapshot"] += time.process_time() - start
        batch.reset([seed])
        start = time.process_time()
        for _ in range(frames):
            batch.step([-2.0], [0.0], only=only)
            world_of_arrays(batch, highway.lanes_count)
        cpu["batch of one step + arrays' world"] += time.process_time() - start
    adapter.close()
    batch.close()
    return {name: 1e3 * seconds / (frames * len(seeds)) for name, seconds in cpu.items()}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1013000)
    parser.add_argument("--scenario", default="highway-v0")
    parser.add_argument("--agent", default="mobil")
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--frames", type=int, default=150, help="frames a world with --traffic-only")
    parser.add_argument("--traffic-only", action="store_true")
    args = parser.parse_args()
    config = build_config(
        {"planner": {"agent": args.agent}, "seed": args.seed},
        scenario=args.scenario,
        highway__duration=args.duration,
    )
    seeds = [args.seed + k for k in range(args.episodes)]
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    if args.traffic_only:
        traffic_only(config.highway, seeds[:1], args.frames)  # numba's kernels loaded
        rates = [traffic_only(config.highway, seeds, args.frames) for _ in range(args.repeats)]
        for name in rates[0]:
            values = [rate[name] for rate in rates]
            shown = " / ".join(f"{value:.3f}" for value in values)
            print(f"| {name} | {shown} | median {statistics.median(values):.3f} |")
        return
    plants = {"vector": HighwayAdapter(config.highway, "vector"), "batch of one": BatchOfOne(config.highway)}
    episodes_cpu(config, plants, seeds[:1])  # imports and numba's kernels loaded
    episodes = f"{args.episodes} x {args.duration:g}-s {args.agent} episodes"
    print(f"{episodes} on {args.scenario}, seeds from {args.seed}")
    print("| repeat | vector ms/frame | batch of one ms/frame | batch of one / vector | same episodes |")
    print("|---|---|---|---|---|")
    for repeat in range(args.repeats):
        cpu, frames, same = episodes_cpu(config, plants, seeds)
        vector, batched = (1e3 * cpu[name] / frames for name in ("vector", "batch of one"))
        print(f"| {repeat} | {vector:.3f} | {batched:.3f} | {batched / vector:.2f} | {same} |")


if __name__ == "__main__":
    main()
