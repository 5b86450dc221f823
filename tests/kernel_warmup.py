"""Compiles the numba kernels the suite calls into drivestack's cache before the test workers start.

numba writes a compiled kernel to its cache (`common.numba_cache`) only once it is compiled, so on a
cold cache every pytest worker compiled the closed loop's kernels itself, at the same time: some
40 CPU-s each, twice. `tests/conftest.py` runs this module's two parts at once, one on each core,
before the workers start: `batched` drives a few tiny episodes as batches of worlds, `per-world`
one world at a time, each also with a tracked sensor and other drivers (the lookahead one world
at a time: it plans on batches itself), so their kernels compile too, and `per-world` (the shorter
part) then a batch seen through a noisy sensor, which compiles the batch's sensor and tracker; the
workers then load every kernel from the cache. A part's failure is not the suite's: the tests
that need the kernel compile it, and fail there if it is broken.

    python -m tests.kernel_warmup batched|per-world
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent

PARTS = ("batched", "per-world")
"""The warm-up's parts, run side by side."""

NOISY_SENSOR = [
    "--set", "perception.sensor.position_noise_m=1.0",
    "--set", "perception.sensor.miss_probability=0.1",
    "--set", "perception.sensor.false_positives=0.5",
]  # fmt: skip
"""The `poor-sensor` scenario's sensor: a batch builds its sensor and tracker only for a sensor
model (a perfect sensor is the truth, tracked or not), so only such a run compiles their kernels."""


def tiny_config(folder: Path) -> Path:
    """configs/highway.yaml with 10 vehicles and 2-s episodes, written into `folder`."""
    data = yaml.safe_load((ROOT / "configs/highway.yaml").read_text())
    data["highway"].update(vehicles_count=10, duration=2)
    path = folder / "tiny.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def warm(part: str) -> None:
    """Drive the tiny episodes of `part` (one of `PARTS`), writing their results into a temporary folder."""
    from stack.apps.cli import app

    batched = part == "batched"
    drivers = ["--traffic", "mixed", "--set", "perception.tracker.mode=on"]
    runs = [["--agent", "ddqn"], ["--agent", "mobil" if batched else "lookahead", *drivers]]
    runs = [[*options, "--set", f"sim.batched={batched}"] for options in runs]
    if not batched:
        runs.append(["--agent", "mobil", *NOISY_SENSOR, "--set", "sim.batched=true"])
    with tempfile.TemporaryDirectory() as folder:
        config = str(tiny_config(Path(folder)))
        for index, options in enumerate(runs):
            arguments = ["run", "-c", config, *options, "--episodes", "2"]
            app([*arguments, "--out", f"{folder}/run{index}", "--no-progress"], standalone_mode=False)
    if not batched:
        rank_a_stopped_car_ahead()


def rank_a_stopped_car_ahead() -> None:
    """The lookahead's ranking of one scene, as its own tests call it (its per-world kernels; a lane
    on each side counted as an int, as `read_scene` counts it)."""
    from planner.lookahead import LookaheadAgent
    from planner.lookahead_scene import Scene
    from records import GridConfig

    lane, one = np.zeros(1, np.int64), np.ones(1)
    LookaheadAgent(GridConfig()).rank(Scene(25.0, 1, 1, lane, 120 * one, 5 * one, 0 * one))


if __name__ == "__main__":
    warm(sys.argv[1])
