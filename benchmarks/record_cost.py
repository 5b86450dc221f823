"""What `--record` costs an episode: CPU time with and without a rerun recording, and the file's size,
in one sitting.

    .venv/bin/python benchmarks/record_cost.py [--seeds 880000,880001,880002] [--agent ddqn] [--duration 40]
        [--repeats 3]

CPU seconds (process time, so rerun's own writer threads count) of whole episodes of the default
config (40 s, 50 vehicles, vector backend), plain and recorded alternating in one process, each
seed `--repeats` times, after a 2-s episode of each (imports, compiled kernels and rerun loaded: a
process pays those once, reported apart). Per seed the fastest of the repeats counts (the least
disturbed on a shared machine). A recorded episode's time includes writing its file. The two must
drive the same episode (same results). Targets: <= 15 % more CPU time, <= 5 MB per 40-s episode.
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

from stack.runs.episodes import run_episode
from stack.settings.run import build_config


def cpu_seconds(config: object, episode: int, record: Path | None) -> tuple[float, object]:
    """(CPU seconds, result) of episode `episode` of `config`, recorded into `record` if given."""
    start = time.process_time()
    result = run_episode(config, episode, record=record)  # type: ignore[arg-type]
    return time.process_time() - start, result


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", default="880000,880001,880002")
    parser.add_argument("--agent", default="ddqn")
    parser.add_argument("--duration", type=float, default=40.0, help="episode length [s]")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each episode, the fastest counts")
    arguments = parser.parse_args()
    seeds = [int(seed) for seed in arguments.seeds.split(",")]
    data = {"planner": {"agent": arguments.agent}}
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        warm = build_config(data, highway__duration=2.0)
        start = time.process_time()
        run_episode(warm, 0)
        first_plain = time.process_time() - start
        start = time.process_time()
        run_episode(warm, 0, record=out / "warm")
        first_recorded = time.process_time() - start
        plain_total = recorded_total = 0.0
        sizes = []
        print(
            f"{platform.machine()}, Python {platform.python_version()}, {arguments.agent}, "
            f"{arguments.duration:g}-s episodes, fastest of {arguments.repeats}, {time.strftime('%Y-%m-%d')}"
        )
        print("| seed | plain CPU s | recorded CPU s | ratio | file MB |\n|---|---|---|---|---|")
        for seed in seeds:
            config = build_config({**data, "seed": seed}, highway__duration=arguments.duration)
            plain = recorded = float("inf")
            for _ in range(arguments.repeats):
                plain_time, plain_result = cpu_seconds(config, 0, None)
                recorded_time, recorded_result = cpu_seconds(config, 0, out / str(seed))
                assert plain_result == recorded_result, "recording changed the episode"
                plain, recorded = min(plain, plain_time), min(recorded, recorded_time)
            size = (out / str(seed) / "episode-0000.rrd").stat().st_size / 1e6
            plain_total, recorded_total = plain_total + plain, recorded_total + recorded
            sizes.append(size)
            print(f"| {seed} | {plain:.2f} | {recorded:.2f} | {recorded / plain:.3f} | {size:.2f} |")
        print(
            f"| all | {plain_total:.2f} | {recorded_total:.2f} | {recorded_total / plain_total:.3f} "
            f"| {max(sizes):.2f} max |"
        )
        print(
            f"once per process: first 2-s episode {first_plain:.2f} s plain, then the first recorded "
            f"one {first_recorded:.2f} s (rerun and pyarrow loaded)"
        )


if __name__ == "__main__":
    main()
