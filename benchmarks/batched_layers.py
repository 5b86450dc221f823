"""CPU time of the layers' batched kernels against their per-world code, on worlds the closed loop
drove on `random` (2-6 lanes, trucks, incidents, sensor noise): the observation encoding
(`perception.grid.observe_batch` against `OccupancyGridBuilder.build(world).encode`) and the
safety layer's permitted commands (`planner.safety.permitted_batch` against the same
decisions made one world at a time by `SafetyLayer.permits` on a fresh copy of each snapshot, whose
neighbour search would otherwise be kept from the last repeat), per world, at several batch sizes.

    .venv/bin/python benchmarks/batched_layers.py [--worlds 1,16,64,256] [--repeats 20]
"""

from __future__ import annotations

import argparse
import copy
import time
from collections.abc import Callable

import numpy as np

from perception.grid import OccupancyGridBuilder, observe_batch
from planner.safety import SafetyLayer, permitted_batch
from records import Command, GridConfig, WorldState
from records.batch import WorldBatch
from stack.loop.closed_loop import ClosedLoop
from stack.settings.run import build_config
from stack.sim.highway import HighwayAdapter

GRID = GridConfig(
    lanes="ego", lateral_reach=2, features=("relative_speed", "ttc", "ego_speed"), lane_code="sides"
)
"""An ego-relative grid with every batched feature (one size on any road)."""


def driven(worlds: int) -> list[WorldState]:
    """`worlds` snapshots, one a second of 20-s lane-keeping episodes on `random`."""
    config = build_config({"highway": {"duration": 20}}, scenario="random")
    found: list[WorldState] = []
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter)
        seed = 0
        while len(found) < worlds:
            loop.reset(seed)
            while not loop.done and len(found) < worlds:
                if loop.world.time % 1.0 < loop.plant.dt / 2:
                    found.append(loop.perceived)
                loop.tick()
            seed += 1
    return found


def cpu_per_world(work: Callable[[], object], worlds: int, repeats: int) -> float:
    """Median CPU seconds of `work` over `repeats`, per world."""
    work()
    times = []
    for _ in range(repeats):
        start = time.process_time()
        work()
        times.append(time.process_time() - start)
    return float(np.median(times)) / worlds


def measured(chosen: list[WorldState], repeats: int) -> tuple[float, float, float, float]:
    """CPU seconds per world: the grid alone and batched, the permitted commands alone and batched."""
    builder, safety = OccupancyGridBuilder(GRID), SafetyLayer(build_config({}).planner.safety)
    batch, size = WorldBatch.of(chosen), len(chosen)
    lanes = np.array([world.ego_lane for world in chosen])

    def grids_alone() -> None:
        for world in chosen:
            builder.build(world).encode("observation")

    def permitted_alone() -> None:
        for world, lane in zip(chosen, lanes, strict=True):
            fresh = copy.copy(world)  # a snapshot's neighbours are kept while it lives
            for command in (Command.LEFT, Command.RIGHT):
                safety.permits(command, fresh, int(lane))

    def permitted_together() -> None:
        permitted_batch(safety.config, batch, lanes, np.zeros(size, dtype=bool), batch.speed[:, 0], 3.0)

    return (
        cpu_per_world(grids_alone, size, repeats),
        cpu_per_world(lambda: observe_batch(GRID, batch), size, repeats),
        cpu_per_world(permitted_alone, size, repeats),
        cpu_per_world(permitted_together, size, repeats),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worlds", default="1,16,64,256")
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    sizes = [int(size) for size in args.worlds.split(",")]
    worlds = driven(max(sizes))
    print("| worlds | grid per world µs | batched µs | ratio | permitted per world µs | batched µs | ratio |")
    print("|---|---|---|---|---|---|---|")
    for size in sizes:
        grid_alone, grid_batched, safety_alone, safety_batched = measured(worlds[:size], args.repeats)
        cells = [f"{grid_alone * 1e6:.1f}", f"{grid_batched * 1e6:.1f}", f"{grid_alone / grid_batched:.1f}x"]
        cells += [
            f"{safety_alone * 1e6:.1f}",
            f"{safety_batched * 1e6:.1f}",
            f"{safety_alone / safety_batched:.1f}x",
        ]
        print(f"| {size} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
