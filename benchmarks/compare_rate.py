"""`drivestack compare` of 4 agents x 200 `overtaking` episodes, on batched worlds (the default) and
one world at a time (`--set sim.batched=false`): wall and CPU time of each, their ratio, and whether
both write the same episodes.

    .venv/bin/python benchmarks/compare_rate.py [--episodes 200] [--jobs 2] [--repeats 1]

Each mode is a fresh `python -m stack compare` process (start-up and the process pool's spawned
interpreters included: what a user waits for) on the same seeds; the modes take turns, in a rotated
order each repeat, and the median is reported, so a load that drifts during the measurement does
not favour one mode. CPU time is the process's and its workers' (user + system).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MODES = (("batched worlds", []), ("one world at a time", ["--set", "sim.batched=false"]))


def children_cpu() -> float:
    """CPU seconds (user + system) of every child process waited for so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed_compare(arguments: list[str], out: Path) -> tuple[float, float, bytes]:
    """(wall [s], CPU [s], episodes.csv) of one `compare` process writing to `out`."""
    command = [sys.executable, "-m", "stack", "compare", *arguments, "--out", str(out), "--no-progress"]
    cpu, start = children_cpu(), time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - start, children_cpu() - cpu, (out / "episodes.csv").read_bytes()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    common = ["--scenario", "overtaking", "--episodes", str(args.episodes), "--seed", "100"]
    common += ["--jobs", str(args.jobs)]
    walls: dict[str, list[float]] = {name: [] for name, _ in MODES}
    cpus: dict[str, list[float]] = {name: [] for name, _ in MODES}
    written: dict[str, bytes] = {}
    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(args.repeats):
            turn = repeat % len(MODES)
            for index, (name, mode) in enumerate(MODES[turn:] + MODES[:turn]):
                wall, cpu, episodes = timed_compare(common + mode, Path(scratch) / f"{repeat}-{index}")
                walls[name].append(wall)
                cpus[name].append(cpu)
                written.setdefault(name, episodes)
    wall = {name: statistics.median(values) for name, values in walls.items()}
    cpu = {name: statistics.median(values) for name, values in cpus.items()}
    machine = platform.processor() or platform.machine()
    load = os.getloadavg()[0]
    print(f"{machine}, {os.cpu_count()} CPUs, python {platform.python_version()}, load average {load:.1f}")
    print(f"compare {' '.join(common)} (ddqn, rule, mobil, keep-lane); median of {args.repeats}")
    print("| mode | wall s | CPU s | wall vs one world at a time |")
    print("|---|---|---|---|")
    alone = MODES[1][0]
    for name, _ in MODES:
        print(f"| {name} | {wall[name]:.1f} | {cpu[name]:.1f} | {wall[alone] / wall[name]:.2f}x |")
    same = len(set(written.values())) == 1
    print(f"episodes.csv identical: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
