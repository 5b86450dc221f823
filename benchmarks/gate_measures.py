"""Compare disagreement measures offline on what `benchmarks/gate_record.py` recorded (issue #71):
per world, the AUROC of each measure for each bad-outcome label, and the share of decisions each
would hand over at the threshold that hands over `--share` of the training worlds' decisions.

    PYTHONPATH=. .venv/bin/python benchmarks/gate_measures.py runs/gate-record [--share 0.02]

Labels (within the recording's horizon after the decision): `unsafe` a TTC below 1.5 s, an
emergency braking of any cause or a collision; `unsafe, ours` the same without the emergency
brakings the decision cannot have caused (a cut-in, a leader's hard braking, a phantom: what the
decision could change is the ego's own lane change or its closing in); `not lookahead's` the
lookahead on the same reading would take another command; `either` unsafe or not the lookahead's.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from uncertainty_gate import auroc  # noqa: E402

from planner.uncertainty import (  # noqa: E402
    advantage_disagreement,
    advantage_ratio,
    coefficient_of_variation,
    compared_as_chosen,
    disagreement,
    dissenting_share,
)
from stack.fault.emergency_causes import CAUSES  # noqa: E402

OURS = [CAUSES.index("own_lane_change"), CAUSES.index("closing_in")]


def permitted_margin(rated: np.ndarray, permitted: np.ndarray) -> np.ndarray:
    """The mean Q's margin of its best permitted command over the next permitted (0: one permitted)."""
    ranked = np.sort(np.where(permitted > 0.5, rated, -np.inf), axis=1)
    return np.where(np.isfinite(ranked[:, -2]), ranked[:, -1] - ranked[:, -2], np.inf)


Record = dict[str, np.ndarray]
MEASURES: dict[str, Callable[[Record], np.ndarray]] = {
    "std Q(chosen)": lambda r: disagreement(r["q"], r["chosen"]),
    "CV Q(chosen)": lambda r: coefficient_of_variation(r["q"], r["chosen"]),
    "std advantage": lambda r: advantage_disagreement(r["q"], r["chosen"], r["permitted"]),
    "votes against": lambda r: dissenting_share(r["q"], r["chosen"], r["permitted"]),
    "advantage ratio": lambda r: advantage_ratio(r["q"], r["chosen"], r["permitted"]),
    "-margin top two": lambda r: -permitted_margin(r["rated"], r["permitted"]),
    "mean std all Q": lambda r: r["q"].std(axis=0).mean(axis=1),
    "std / speed": lambda r: disagreement(r["q"], r["chosen"]) / np.maximum(r["speed"], 1.0),
    "votes + std adv": lambda r: (
        dissenting_share(r["q"], r["chosen"], r["permitted"])
        + 1e-3 * advantage_disagreement(r["q"], r["chosen"], r["permitted"])
    ),
    "advantage ratio x std Q(chosen)": lambda r: (
        advantage_ratio(r["q"], r["chosen"], r["permitted"]) * disagreement(r["q"], r["chosen"])
    ),
}


def load(path: Path) -> Record:
    """One world's recording, its members' Q-values (members, batch, 3) with the MOBIL prior's
    bonus (the same for every member) added, as the ensemble's choice compares them."""
    data = dict(np.load(path))
    data["q"] = compared_as_chosen(np.transpose(data["member_q"], (1, 0, 2)), data["rated"])
    braking = data["braking"]
    data["unsafe"] = data["ttc"] | (braking.sum(axis=1) > 0) | data["crashed"]
    data["unsafe, ours"] = data["ttc"] | (braking[:, OURS].sum(axis=1) > 0) | data["crashed"]
    data["not lookahead's"] = data["chosen"] != data["lookahead"]
    data["either"] = data["unsafe"] | data["not lookahead's"]
    return data


LABELS = ("unsafe", "unsafe, ours", "not lookahead's", "either")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("folder", type=Path)
    parser.add_argument("--share", type=float, default=0.02, help="handed over in distribution")
    args = parser.parse_args()
    worlds = {path.stem: load(path) for path in sorted(args.folder.glob("*.npz"))}
    training = {name: data for name, data in worlds.items() if name.startswith("train_")}
    pooled = {key: np.concatenate([data[key] for data in training.values()]) for key in ("chosen", "speed")}
    pooled["q"] = np.concatenate([data["q"] for data in training.values()], axis=1)
    for key in ("rated", "permitted", "braking", *LABELS):
        pooled[key] = np.concatenate([data[key] for data in training.values()])
    thresholds = {
        name: float(np.quantile(np.nan_to_num(measure(pooled), posinf=1e12), 1 - args.share))
        for name, measure in MEASURES.items()
    }
    shown = {
        "training worlds (pooled)": pooled,
        **{k: v for k, v in worlds.items() if k.startswith("probe_")},
    }
    for world, data in shown.items():
        counts = ", ".join(f"{label} {np.mean(data[label]):.1%}" for label in LABELS)
        print(f"\n## {world}: {data['chosen'].size} decisions; {counts}")
        causes = data["braking"].sum(axis=0) if "braking" in data else None
        if causes is not None and causes.sum():
            print(
                "   emergency brakings in a window, by cause: "
                + ", ".join(
                    f"{cause} {int(count)}" for cause, count in zip(CAUSES, causes, strict=True) if count
                )
            )
        print("measure | " + " | ".join(f"AUROC {label}" for label in LABELS) + " | handed over")
        for name, measure in MEASURES.items():
            values = np.nan_to_num(measure(data), posinf=1e12)
            cells = []
            for label in LABELS:
                found = auroc(values.tolist(), data[label].tolist())
                cells.append("n/a" if found is None else f"{found:.2f}")
            print(f"{name} | " + " | ".join(cells) + f" | {np.mean(values > thresholds[name]):.1%}")


if __name__ == "__main__":
    main()
