"""The tracker's cost on batched worlds, a world-frame at a time, in one sitting.

    .venv/bin/python benchmarks/tracker_cost.py [--scenario poor-sensor] [--worlds 64] [--decisions 11]
        [--rounds 5] [--seed 1028200] [--digest]

Records what `perception.tracking.TrackerBatch` is given over `--decisions` decisions of `--worlds`
worlds (`stack.training.gym_vector_env.DecisionVecEnv`, seeded random commands, the tracker on),
then replays it into a fresh `TrackerBatch`, timing `update` (the law, `track_worlds`, and the
report) and the compiled law alone, each world-frame a tracked world's frame (warm-up frames
included). `whole`: the same decisions stepped with the tracker on and with it off, the
difference a world-frame (15 frames a decision) what tracking costs the batch, downstream
(emergency braking's memory, the grid over more rows) included. Rounds alternate the measures,
so the machine's load hits them alike; figures are medians and ranges of `time.process_time`.
`--digest`: a SHA-256 of every replayed report (what the tracker reports, bit for bit), to
compare two versions of the law.

    .venv/bin/python benchmarks/tracker_cost.py --per-world [--agent mobil] [--episodes 2]
        [--duration 10] [--rounds 5]

`--per-world`: one world at a time (`stack.runs.episodes.run_episode`, the vector backend), the
same seeded episodes with the tracker on and off alternating, ms a frame of each, and the time
inside `perception.tracking.Tracker.update` of the episodes on, a frame: the tracker's own share,
which the machine's load does not blur as it blurs the difference of two whole runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import hashlib
import os
import statistics
import time
from typing import Any

import numpy as np
from batched_decisions import batch_rate

from perception.track_records import MeasuredWorlds
from perception.tracking import Tracker, TrackerBatch, lane_velocity
from perception.tracking_kernels import track_worlds
from records.batch import WorldBatch
from stack.settings.run import RunConfig, build_config

Event = tuple[str, Any, Any, Any]
"""("reset", world, sensor, None) or ("update", sensed batch, flagged worlds, dt)."""


def _copied(batch: WorldBatch) -> WorldBatch:
    arrays = {field.name: np.copy(getattr(batch, field.name)) for field in dataclasses.fields(batch)}
    arrays["lane_width"] = batch.lane_width
    return dataclasses.replace(batch, **arrays)


def _run(config: RunConfig, worlds: int, decisions: int, seed: int) -> float:
    """Process seconds `decisions` seeded random decisions of `worlds` worlds take (resets out)."""
    return worlds * decisions / batch_rate(config, worlds, seed, decisions)


def capture(config: RunConfig, worlds: int, decisions: int, seed: int) -> list[Event]:
    """What a `TrackerBatch` is given over `_run`, in order."""
    events: list[Event] = []
    update, reset_world = TrackerBatch.update, TrackerBatch.reset_world

    def recorded_update(self: TrackerBatch, sensed: WorldBatch, flagged: np.ndarray, dt: float) -> Any:
        events.append(("update", _copied(sensed), np.array(flagged, dtype=bool), dt))
        return update(self, sensed, flagged, dt)

    def recorded_reset(self: TrackerBatch, world: int, sensor: Any) -> None:
        events.append(("reset", world, sensor, None))
        reset_world(self, world, sensor)

    TrackerBatch.update, TrackerBatch.reset_world = recorded_update, recorded_reset  # type: ignore[method-assign]
    try:
        _run(config, worlds, decisions, seed)
    finally:
        TrackerBatch.update, TrackerBatch.reset_world = update, reset_world  # type: ignore[method-assign]
    return events


def world_frames(tracker: TrackerBatch, events: list[Event]) -> int:
    """Tracked world-frames of `events` (replayed into `tracker`)."""
    frames = 0
    for kind, first, second, _ in events:
        if kind == "reset":
            tracker.reset_world(first, second)
        else:
            frames += int((second & tracker.tracked).sum())
            tracker.update(first, second, 0.0)
    return frames


def replay(config: RunConfig, worlds: int, events: list[Event], law_only: bool, digest: Any = None) -> float:
    """Process seconds the `update` calls of `events` take in a fresh `TrackerBatch` (only its
    compiled law, `track_worlds`, when `law_only`), each report hashed into `digest`."""
    tracker = TrackerBatch(config.perception.tracker, worlds)
    elapsed = 0.0
    for kind, first, second, dt in events:
        if kind == "reset":
            tracker.reset_world(first, second)
            continue
        if not law_only:
            start = time.process_time()
            tracked = tracker.update(first, second, dt)
            elapsed += time.process_time() - start
            if digest is not None:
                for name in ("count", "s", "d", "speed", "heading", "length", "width", "lane"):
                    digest.update(np.ascontiguousarray(getattr(tracked.batch, name)).tobytes())
                digest.update(tracked.slot.tobytes())
            continue
        sensed = first
        along, across, relative = lane_velocity(sensed.speed, sensed.heading, sensed.lane_heading[:, None])
        found = MeasuredWorlds(
            sensed.count, sensed.s, sensed.d, along, across, sensed.length, sensed.width, relative
        )
        flagged = second & tracker.tracked
        heading = np.ascontiguousarray(sensed.lane_heading, dtype=np.float64)
        work = tracker.work.fit(sensed.s.shape[1] - 1)
        start = time.process_time()
        track_worlds(
            tracker.law, tracker.tracks, found, tracker.position_variance, dt, flagged, sensed.lane_offsets,
            sensed.lanes_count, heading, tracker.slots, tracker.lanes, tracker.rows, tracker.counts,
            work.integers, work.floats,
        )  # fmt: skip
        elapsed += time.process_time() - start
    return elapsed


def _summary(values: list[float], digits: int = 1) -> str:
    return f"{statistics.median(values):.{digits}f} ({min(values):.{digits}f} to {max(values):.{digits}f})"


def per_world(scenario: str, agent: str, episodes: int, duration: float, rounds: int, seed: int) -> None:
    """ms a frame of `episodes` seeded episodes run one world at a time with the tracker on and off
    (alternating, the order reversed every other round), and of `Tracker.update` inside them."""
    from stack.runs.episodes import run_episode

    configs = {
        mode: build_config(
            {"planner": {"agent": agent}, "seed": seed, "perception": {"tracker": {"mode": mode}}},
            scenario=scenario,
            highway__duration=duration,
        )
        for mode in ("on", "off")
    }
    inside = [0.0]
    update = Tracker.update

    def timed_update(self: Tracker, detected: Any, dt: float) -> Any:
        start = time.process_time()
        tracked = update(self, detected, dt)
        inside[0] += time.process_time() - start
        return tracked

    for config in configs.values():
        run_episode(config, 0)  # imports, caches and the process's env warmed up
    ms: dict[str, list[float]] = {"on": [], "off": [], "tracker": []}
    Tracker.update = timed_update  # type: ignore[method-assign]
    try:
        for round_ in range(rounds):
            for mode in ("on", "off") if round_ % 2 == 0 else ("off", "on"):
                inside[0], frames, elapsed = 0.0, 0, 0.0
                for episode in range(episodes):
                    start = time.process_time()
                    frames += run_episode(configs[mode], episode).steps
                    elapsed += time.process_time() - start
                ms[mode].append(1e3 * elapsed / frames)
                if mode == "on":
                    ms["tracker"].append(1e3 * inside[0] / frames)
    finally:
        Tracker.update = update  # type: ignore[method-assign]
    ratios = [100 * (on / off - 1) for on, off in zip(ms["on"], ms["off"], strict=True)]
    shares = [100 * inside / on for inside, on in zip(ms["tracker"], ms["on"], strict=True)]
    print(f"load after {os.getloadavg()[0]:.1f}; ms a frame, median (range) of {rounds} rounds:")
    print(f"on {_summary(ms['on'], 3)}, off {_summary(ms['off'], 3)}, on/off - 1 {_summary(ratios)} %")
    print(f"Tracker.update {_summary(ms['tracker'], 4)} ms a frame, {_summary(shares)} % of a frame on")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenario", default="poor-sensor")
    parser.add_argument("--worlds", type=int, default=64)
    parser.add_argument("--decisions", type=int, default=11)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seed", type=int, default=1028200)
    parser.add_argument("--digest", action="store_true", help="only the SHA-256 of every replayed report")
    parser.add_argument("--per-world", action="store_true", help="one world at a time, on against off")
    parser.add_argument("--agent", default="mobil", help="with --per-world")
    parser.add_argument("--episodes", type=int, default=2, help="with --per-world")
    parser.add_argument("--duration", type=float, default=10.0, help="episode length [s] with --per-world")
    args = parser.parse_args()
    now = datetime.datetime.now(datetime.UTC)
    if args.per_world:
        print(f"{now:%Y-%m-%d %H:%M} UTC, load {os.getloadavg()[0]:.1f}, scenario {args.scenario}, one world")
        per_world(args.scenario, args.agent, args.episodes, args.duration, args.rounds, args.seed)
        return
    configs = {
        mode: build_config({"perception": {"tracker": {"mode": mode}}}, scenario=args.scenario)
        for mode in ("on", "off")
    }
    events = capture(configs["on"], args.worlds, args.decisions, args.seed)
    if args.digest:
        digest = hashlib.sha256()
        replay(configs["on"], args.worlds, events, law_only=False, digest=digest)
        print(digest.hexdigest())
        return
    frames = world_frames(TrackerBatch(configs["on"].perception.tracker, args.worlds), events)
    config = configs["on"]
    whole_frames = args.worlds * args.decisions * config.decision_ticks
    print(
        f"{now:%Y-%m-%d %H:%M} UTC, load {os.getloadavg()[0]:.1f}, scenario {args.scenario}, "
        f"{args.worlds} worlds, {args.decisions} decisions, {frames} tracked world-frames"
    )
    _run(configs["off"], 2, 1, args.seed)  # compiled, loaded
    µs: dict[str, list[float]] = {"update": [], "law": [], "on": [], "off": []}
    for round_ in range(args.rounds):
        modes = ("on", "off") if round_ % 2 == 0 else ("off", "on")
        for mode in modes:
            µs[mode].append(1e6 * _run(configs[mode], args.worlds, args.decisions, args.seed) / whole_frames)
        µs["update"].append(1e6 * replay(config, args.worlds, events, law_only=False) / frames)
        µs["law"].append(1e6 * replay(config, args.worlds, events, law_only=True) / frames)
    whole = [on - off for on, off in zip(µs["on"], µs["off"], strict=True)]
    print(f"load after {os.getloadavg()[0]:.1f}; µs a world-frame, median (range) of {args.rounds} rounds:")
    print(f"TrackerBatch.update {_summary(µs['update'])}, the law {_summary(µs['law'])}")
    print(f"whole decisions: on {_summary(µs['on'])}, off {_summary(µs['off'])}, on - off {_summary(whole)}")


if __name__ == "__main__":
    main()
