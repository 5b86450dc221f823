"""Grid build time next to a highway-env physics frame and highway-env's own OccupancyGrid.

    .venv/bin/python benchmarks/grid_speed.py [--repeats 300]

For 10, 50 and 100 vehicles (highway-v0, 4 lanes, density 1 / 1 / 2), after 60 frames of traffic:
median and p95 of `OccupancyGridBuilder.build` (footprint mode, the default grid), of highway-env's
`OccupancyGridObservation.observe()` (presence only, same cells), and of one stock physics frame.
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import numpy as np
from highway_env.envs.common.observation import OccupancyGridObservation

from perception.grid import GridConfig, OccupancyGridBuilder
from records import Actuation
from stack.settings.run import HighwayConfig
from stack.sim.highway import HighwayAdapter


def timings(function, repeats: int) -> tuple[float, float]:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        samples.append(time.perf_counter() - start)
    return float(np.median(samples)) * 1e6, float(np.percentile(samples, 95)) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=300)
    args = parser.parse_args()
    config = GridConfig(cells_ahead=9, cells_behind=4)
    builder = OccupancyGridBuilder(config)
    print(
        "| vehicles | our build µs (median / p95) | highway-env observe() µs"
        " | stock frame incl. snapshot µs | build / frame |"
    )
    print("|---|---|---|---|---|")
    for vehicles, density in ((10, 1.0), (50, 1.0), (100, 2.0)):
        with HighwayAdapter(
            HighwayConfig(vehicles_count=vehicles, vehicles_density=density), "stock"
        ) as adapter:
            world = adapter.reset(0)
            for _ in range(60):
                world = adapter.step(Actuation(0.0, 0.0))
            L, width = config.cell_length, world.lane_width
            y_low = -world.d[0] - width / 2
            theirs = OccupancyGridObservation(
                adapter.env.unwrapped,
                features=["presence"],
                grid_size=[
                    [-(config.cells_behind + 0.5) * L, (config.cells_ahead - 0.5) * L],
                    [y_low, y_low + world.lanes_count * width],
                ],
                grid_step=[L, width],
            )
            ours = timings(partial(builder.build, world), args.repeats)
            observe = timings(theirs.observe, max(20, args.repeats // 10))
            frame = timings(lambda: adapter.step(Actuation(0.0, 0.0)), 100)
        print(
            f"| {world.count} | {ours[0]:.0f} / {ours[1]:.0f} | {observe[0]:.0f} / {observe[1]:.0f} "
            f"| {frame[0]:.0f} / {frame[1]:.0f} | {100 * ours[0] / frame[0]:.2f} % |",
            flush=True,
        )


if __name__ == "__main__":
    main()
