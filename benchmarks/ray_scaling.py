"""`drivestack compare` over 1 and 2 local processes and on a local Ray instance: wall time and
whether the three give the same comparison.

    .venv/bin/python benchmarks/ray_scaling.py [--agents rule,mobil,keep-lane,ddqn] [--episodes 20]
                                               [--repeats 3] [--set highway.duration=40 ...]

Each mode is a fresh `python -m stack compare` process on the same seeds, so the wall time includes
what a user waits for: the process pool's spawned interpreters, or starting Ray (one CPU per core)
and its workers. The modes take turns, in a rotated order each repeat, and the median is reported,
so a load that drifts during the measurement (a shared machine) does not favour one mode. Needs the
ray extra (pip install 'drivestack[ray]').
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from stack.results.episode_result import outcome

MODES = (("--jobs 1", ["--jobs", "1"]), ("--jobs 2", ["--jobs", "2"]), ("--ray (local)", ["--ray", "local"]))


def timed_compare(arguments: list[str], out: Path) -> tuple[float, list]:
    """(wall time [s], comparison.json rows without their timing fields) of one `compare` process
    writing to `out`."""
    command = [sys.executable, "-m", "stack", "compare", *arguments, "--out", str(out), "--no-progress"]
    start = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    rows = json.loads((out / "comparison.json").read_text())
    return time.perf_counter() - start, [outcome(row) for row in rows]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--agents", default="rule,mobil,keep-lane,ddqn")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--set", dest="sets", action="append", default=[], help="KEY=VALUE, as drivestack")
    args = parser.parse_args()
    common = ["--agents", args.agents, "--episodes", str(args.episodes)]
    common += [word for entry in args.sets for word in ("--set", entry)]
    walls: dict[str, list[float]] = {name: [] for name, _ in MODES}
    comparisons: dict[str, list[list]] = {name: [] for name, _ in MODES}
    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(args.repeats):
            for index, (name, mode) in enumerate(MODES[repeat % len(MODES) :] + MODES[: repeat % len(MODES)]):
                wall, comparison = timed_compare(common + mode, Path(scratch) / f"{repeat}-{index}")
                walls[name].append(wall)
                comparisons[name].append(comparison)
    median = {name: statistics.median(times) for name, times in walls.items()}
    reference, serial = comparisons[MODES[0][0]][0], median[MODES[0][0]]
    machine = platform.processor() or platform.machine()
    load = os.getloadavg()[0]
    print(f"{machine}, {os.cpu_count()} CPUs, python {platform.python_version()}, load average {load:.1f}")
    print(f"compare {' '.join(common)}; median of {args.repeats}")
    print("| mode | wall time s | speed-up vs --jobs 1 | summaries identical to --jobs 1 |")
    print("|---|---|---|---|")
    for name, _ in MODES:
        same = "yes" if all(comparison == reference for comparison in comparisons[name]) else "NO"
        print(f"| {name} | {median[name]:.1f} | {serial / median[name]:.2f}x | {same} |")
    jobs2, ray = median["--jobs 2"], median["--ray (local)"]
    print(f"--ray / --jobs 2 wall time: {ray / jobs2:.2f}")


if __name__ == "__main__":
    main()
