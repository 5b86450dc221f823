"""`drivestack --help` wall time: what a user waits for before any command runs.

    .venv/bin/python benchmarks/cli_startup.py [--runs 7]

Median of `--runs` fresh processes; the heavy libraries (torch, python-control, CasADi, highway-env's
envs) are imported only by the commands that need them.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    command = [shutil.which("drivestack") or sys.executable, "--help"]
    if command[0] == sys.executable:
        command = [sys.executable, "-m", "stack", "--help"]
    times = []
    for _ in range(args.runs):
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        times.append(time.perf_counter() - start)
    print(f"drivestack --help: median {statistics.median(times):.2f} s wall over {args.runs} runs")


if __name__ == "__main__":
    main()
