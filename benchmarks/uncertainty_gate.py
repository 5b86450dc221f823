"""The uncertainty gate on worlds the shipped ddqn never trained on (issue #71): per probe, how well
the ensemble's disagreement predicts a bad outcome (AUROC), the share of decisions the gate hands to
the lookahead, and the outcomes with and without the gate, on the same seeds.

    PYTHONPATH=. .venv/bin/python benchmarks/uncertainty_gate.py --model runs/ddqn-gated.npz \\
        [--episodes 30] [--seed 1005000] [--horizon 3] [--probes "7 lanes,mixed drivers"]

(`--model`: a file `drivestack gate-calibrate` wrote.) With `--in-distribution N`, instead, the
share the gate hands over on N episodes of each world of the training mix from `--seed`.

Two bad outcomes are measured. Unsafe: within `--horizon` seconds of the decision, the ego's time
to collision with a leader drops below 1.5 s (`TTC_FLOOR_S`), emergency braking fires, or it
collides (what the safety monitor measures on every tick). Not the planner's: the lookahead, on the
same sensor reading, would take another command (a proxy for the oracle's verdict, which costs a
search a decision; the lookahead is within about 0.5 m/s of the ddqn on every named scenario).
Either: one or the other (the issue's bad outcome). The AUROCs are the no-gate arm's (the ensemble
decides everything), for the measure the model file's threshold was calibrated for (what the gate
reads, `planner.uncertainty.MEASURES`) and for Hoel et al.'s coefficient of variation of
Q(chosen). Both arms run one world at a time (`ClosedLoop`), episode k of a probe with seed `--seed` + k.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import rankdata

from planner.agents import decide
from planner.factory import make_agent
from planner.learned import LearnedAgent, load_agent
from planner.uncertainty import gate_measure
from stack.apps.gate import LoggedGate, calibrate, calibration_table
from stack.apps.options import TRAIN_CONFIG
from stack.loop.closed_loop import ClosedLoop
from stack.runs.alone import agent_step
from stack.runs.kept import kept_adapter, lookahead_setup
from stack.settings.run import RunConfig, build_config, grid_config, load_config

RACERS = {
    "ego_position": 0.5,
    "spawn_speed_mps": 18,
    "classes": [
        {
            "name": "truck",
            "share": 0.4,
            "speed_mps": [16, 20],
            "length_m": [10, 12],
            "lanes": [2, 3],
            "changes_lane": False,
        },
        {"name": "car", "share": 0.4, "speed_mps": [23, 31], "length_m": [4.5, 5.0]},
        {"name": "racer", "share": 0.2, "speed_mps": [45, 55], "length_m": [4.5, 5.0]},
    ],
}
PROBES: dict[str, tuple[str, dict[str, object]]] = {
    "overtaking (in distribution)": ("overtaking", {}),
    "racers 45-55 m/s": ("overtaking", {"highway.traffic": RACERS}),
    "stopped car 60 m ahead": (
        "incident",
        {"highway.traffic.incident.ahead_m": 60, "highway.traffic.spawn_speed_mps": 10},
    ),
    "7 lanes": ("highway-v0", {"highway.lanes_count": 7, "highway.vehicles_count": 80}),
    "heavy sensor noise": (
        "overtaking",
        {"perception.sensor": {"position_noise_m": 2.0, "miss_probability": 0.2, "false_positives": 1.0}},
    ),
    "aggressive drivers": ("overtaking", {"highway.traffic.drivers": "aggressive"}),
    "mixed drivers": ("overtaking", {"highway.traffic.drivers": "mixed"}),
    "distracted drivers": ("overtaking", {"highway.traffic.drivers": "distracted"}),
    "blind drivers": ("overtaking", {"highway.traffic.drivers": "blind"}),
}


@dataclass
class Arm:
    """One arm's decisions (disagreement, variation, handed over, unsafe within the horizon, not
    the lookahead's command) and
    episodes (mean speed, crashed, at fault, emergency brakings, time below the TTC floor)."""

    spread: list[float]
    variation: list[float]
    handed: list[bool]
    bad: list[bool]
    other: list[bool]
    episodes: list[dict[str, float]]


def probe_config(scenario: str, overrides: dict[str, object], model: Path) -> RunConfig:
    return build_config(
        {}, scenario=scenario, **{"planner.agent": "ddqn", "planner.model": model, **overrides}
    )


def run_arm(
    config: RunConfig, learned: LearnedAgent, threshold: float, episodes: int, seed: int, horizon: float
) -> Arm:
    fallback = make_agent(
        "lookahead", config.highway.lanes_count, grid_config(config), lookahead=lookahead_setup(config)
    )
    arm = Arm([], [], [], [], [], [])
    for episode in range(episodes):
        gate = LoggedGate(learned, fallback, threshold, "lookahead", gate_measure(learned.metadata))
        loop = ClosedLoop(config, kept_adapter(config), grid=learned.grid_config)
        loop.reset(seed + episode)
        starts, marks, lookahead_says = [], [], []
        while not loop.done:
            starts.append((loop.world.time, _badness(loop)))
            agent_step(loop, gate)
            view = loop.perceive_as(fallback.grid_config).encode(fallback.encoding)
            lookahead_says.append(int(decide(fallback, view)))
            marks.append((loop.world.time, _badness(loop)))
        for start, before in starts:
            after = next((bad for end, bad in marks if end >= start + horizon), marks[-1][1])
            arm.bad.append(any(a > b for a, b in zip(after, before, strict=True)))
        arm.spread += gate.disagreements
        arm.variation += gate.variations
        arm.handed += gate.handed
        arm.other += [ours != theirs for ours, theirs in zip(gate.actions, lookahead_says, strict=True)]
        result = loop.result(episode)
        arm.episodes.append(
            {
                "mean_speed": result.mean_speed,
                "crashed": float(result.crashed),
                "at_fault": float(result.at_fault_collision),
                "emergency_brakings": float(result.emergency_brakings),
                "below_ttc_floor_s": result.time_below_ttc_floor_s,
                "lane_changes": float(result.lane_changes),
            }
        )
    return arm


def _badness(loop: ClosedLoop) -> tuple[float, int, bool]:
    """What grows when something bad happens: time below the TTC floor [s], emergency brakings,
    a collision."""
    return (float(loop.monitor.kept.time_below_ttc_floor_s[0]), loop.emergency.activations, loop.crashed)


def auroc(scores: list[float], labels: list[bool]) -> float | None:
    """The area under the ROC curve of `scores` for `labels` (Mann-Whitney, ties halved); None
    without both classes."""
    labels_array = np.array(labels, dtype=bool)
    positives, negatives = int(labels_array.sum()), int((~labels_array).sum())
    if not positives or not negatives:
        return None
    ranks = rankdata(np.nan_to_num(np.array(scores, dtype=float), posinf=1e12))
    return float((ranks[labels_array].sum() - positives * (positives + 1) / 2) / (positives * negatives))


def mean_of(arm: Arm, key: str) -> float:
    return float(np.mean([episode[key] for episode in arm.episodes]))


def paired_interval(gated: Arm, plain: Arm, key: str) -> tuple[float, float]:
    """The 95 % interval (normal, paired by seed) of the gated arm's mean `key` minus the plain one's."""
    differences = np.array([a[key] - b[key] for a, b in zip(gated.episodes, plain.episodes, strict=True)])
    half = 1.96 * differences.std(ddof=1) / np.sqrt(differences.size) if differences.size > 1 else np.nan
    return float(differences.mean() - half), float(differences.mean() + half)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--model", type=Path, required=True, help="an ensemble with a calibrated threshold")
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--seed", type=int, default=1005000)
    parser.add_argument(
        "--horizon", type=float, default=3.0, help="[s] a bad outcome counts this long after a decision"
    )
    parser.add_argument("--probes", default=",".join(PROBES))
    parser.add_argument("--out", type=Path, default=Path("runs/uncertainty_gate.json"))
    parser.add_argument(
        "--in-distribution",
        type=int,
        default=0,
        metavar="EPISODES",
        help="instead: the share handed over on EPISODES episodes of each training world from --seed",
    )
    args = parser.parse_args()
    learned = load_agent(args.model, expected_algorithms=("ddqn",))
    assert isinstance(learned, LearnedAgent)
    threshold = learned.metadata.uncertainty_threshold
    if threshold is None:
        raise SystemExit(f"{args.model}: no uncertainty_threshold; run drivestack gate-calibrate first")
    print(f"threshold {threshold:.4f} ({learned.metadata.uncertainty_calibration})")
    print(f"measure {gate_measure(learned.metadata)}")
    if args.in_distribution:
        measure = gate_measure(learned.metadata)
        found = calibrate(
            load_config(TRAIN_CONFIG), args.model, args.in_distribution, args.seed, 98.5, measure
        )
        found.threshold = threshold
        everything = np.concatenate([np.array(values) for values in found.disagreements.values()])
        print(calibration_table(found))
        print(f"handed over: {np.mean(everything > threshold):.1%} of {everything.size} decisions")
        return
    print(
        "probe | decisions | unsafe % | AUROC measure / CV | not the lookahead's % | AUROC measure / CV | "
        "either % | AUROC either | handed over % | speed no gate / gate [gate - no gate 95 %] | "
        "crashes | AEB / ep | below TTC 1.5 s / ep | unsafe % no gate / gate"
    )
    rows = {}
    for name in args.probes.split(","):
        scenario, overrides = PROBES[name]
        config = probe_config(scenario, overrides, args.model)
        started = time.perf_counter()
        plain = run_arm(config, learned, float("inf"), args.episodes, args.seed, args.horizon)
        gated = run_arm(config, learned, threshold, args.episodes, args.seed, args.horizon)
        either = [bad or other for bad, other in zip(plain.bad, plain.other, strict=True)]
        row: dict[str, Any] = {
            "decisions": len(plain.bad),
            "bad_share": float(np.mean(plain.bad)),
            "auroc_std": auroc(plain.spread, plain.bad),
            "auroc_cv": auroc(plain.variation, plain.bad),
            "other_share": float(np.mean(plain.other)),
            "auroc_other_std": auroc(plain.spread, plain.other),
            "auroc_other_cv": auroc(plain.variation, plain.other),
            "either_share": float(np.mean(either)),
            "auroc_either": auroc(plain.spread, either),
            "handed_share": float(np.mean(gated.handed)),
            "would_hand_share": float(np.mean(np.array(plain.spread) > threshold)),
            **{f"{key}_no_gate": mean_of(plain, key) for key in plain.episodes[0]},
            **{f"{key}_gate": mean_of(gated, key) for key in gated.episodes[0]},
            "gate_bad_share": float(np.mean(gated.bad)),
            "speed_difference_interval": paired_interval(gated, plain, "mean_speed"),
            "seconds": time.perf_counter() - started,
        }
        rows[name] = row
        shown = lambda value: "n/a" if value is None else f"{value:.2f}"  # noqa: E731
        print(
            f"{name} | {row['decisions']} | {100 * row['bad_share']:.1f} | {shown(row['auroc_std'])} / "
            f"{shown(row['auroc_cv'])} | {100 * row['other_share']:.1f} | {shown(row['auroc_other_std'])} / "
            f"{shown(row['auroc_other_cv'])} | {100 * row['either_share']:.1f} | "
            f"{shown(row['auroc_either'])} | {100 * row['handed_share']:.1f} | "
            f"{row['mean_speed_no_gate']:.2f} / {row['mean_speed_gate']:.2f} "
            f"[{row['speed_difference_interval'][0]:+.2f}, {row['speed_difference_interval'][1]:+.2f}] | "
            f"{row['crashed_no_gate'] * args.episodes:.0f} / {row['crashed_gate'] * args.episodes:.0f} | "
            f"{row['emergency_brakings_no_gate']:.2f} / {row['emergency_brakings_gate']:.2f} | "
            f"{row['below_ttc_floor_s_no_gate']:.2f} / {row['below_ttc_floor_s_gate']:.2f} s | "
            f"{100 * row['bad_share']:.1f} / {100 * row['gate_bad_share']:.1f}",
            flush=True,
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {"threshold": threshold, "episodes": args.episodes, "seed": args.seed, "probes": rows}, indent=2
        )
    )


if __name__ == "__main__":
    main()
