"""`drivestack compare` over 1 and 2 local processes and on a local Ray instance: wall time and
whether the three give the same comparison.

    .venv/bin/python benchmarks/ray_scaling.py [--agents rule,mobil,keep-lane,ddqn] [--episodes 20]
                                               [--set highway.duration=40 ...]

Each mode is a fresh `python -m stack compare` process on the same seeds, so the wall time includes
what a user waits for: the process pool's spawned interpreters, or starting Ray (one CPU per core)
and its workers. Needs the ray extra (pip install 'drivestack[ray]').
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MODES = (("--jobs 1", ["--jobs", "1"]), ("--jobs 2", ["--jobs", "2"]), ("--ray (local)", ["--ray", "local"]))


def timed_compare(arguments: list[str], out: Path) -> tuple[float, list]:
    """(wall time [s], comparison.json rows) of one `compare` process writing to `out`."""
    command = [sys.executable, "-m", "stack", "compare", *arguments, "--out", str(out), "--no-progress"]
    start = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - start, json.loads((out / "comparison.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--agents", default="rule,mobil,keep-lane,ddqn")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--set", dest="sets", action="append", default=[], help="KEY=VALUE, as drivestack")
    args = parser.parse_args()
    common = ["--agents", args.agents, "--episodes", str(args.episodes)]
    common += [word for entry in args.sets for word in ("--set", entry)]
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for name, mode in MODES:
            wall, comparison = timed_compare(common + mode, Path(scratch) / name.split()[0].strip("-"))
            rows.append((name, wall, comparison))
    reference, serial = rows[0][2], rows[0][1]
    machine = platform.processor() or platform.machine()
    print(f"{machine}, {os.cpu_count()} CPUs, python {platform.python_version()}")
    print(f"compare {' '.join(common)}")
    print("| mode | wall time s | speed-up vs --jobs 1 | summaries identical to --jobs 1 |")
    print("|---|---|---|---|")
    for name, wall, comparison in rows:
        print(
            f"| {name} | {wall:.1f} | {serial / wall:.2f}x | {'yes' if comparison == reference else 'NO'} |"
        )
    jobs2, ray = rows[1][1], rows[2][1]
    print(f"--ray / --jobs 2 wall time: {ray / jobs2:.2f}")


if __name__ == "__main__":
    main()
