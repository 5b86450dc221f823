"""Which state the decision needs: the shipped DDQN config trained with a smaller observation, each
variant for the same budget, then its kept model against MOBIL on selection seeds.

    .venv/bin/python benchmarks/state_ablation.py [--steps 40000] [--episodes 100] [--seed 1000]
        [--variants paper,grid,speeds,reach-2,shipped] [--out runs/ablation]

Every variant keeps the shipped training (scenario mix, reward, validation, 2 envs) and changes only
`perception`; its run folder is `OUT/VARIANT` (resumable: an interrupted variant resumes, a finished
one is not trained again). Evaluation: `overtaking`, seeds `--seed` on (selection seeds, never
report seeds), paired against MOBIL on the same seeds. The table is printed and written to
`OUT/ablation.md`.
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path
from typing import Any

from stack.apps.compare import differences
from stack.runs.episodes import run
from stack.runtime.files import write_text
from stack.settings.run import RunConfig, load_config
from stack.training.trainer import BEST, Trainer

VARIANTS: dict[str, dict[str, Any]] = {
    "paper": {"features": [], "lanes": "absolute", "lane_code": "binary", "lateral_reach": 1},
    "grid": {"features": [], "lateral_reach": 1},
    "speeds": {"features": ["relative_speed", "ttc", "ego_speed"], "lateral_reach": 1},
    "reach-2": {"features": ["relative_speed", "ttc", "ego_speed"], "lateral_reach": 2},
    "shipped": {"features": ["relative_speed", "ttc", "ego_speed", "ego_lateral"], "lateral_reach": 2},
}
"""The observation of each variant: grid features and lanes seen on each side of the ego; `paper` is
the paper's own state, one row per road lane and the ego lane's binary code."""


def trained(config: RunConfig, out: Path) -> Path:
    """The kept model of `config`'s training in `out`: trained first, or resumed from its
    checkpoint, unless a finished run is there."""
    summary = out / "summary.json"
    if not summary.exists() or json.loads(summary.read_text()).get("interrupted"):
        Trainer(config, out, progress=True).run()
    return out / BEST


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=40_000)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--config", default="configs/train/ddqn-stage1.yaml")
    parser.add_argument("--out", type=Path, default=Path("runs/ablation"))
    args = parser.parse_args()
    evaluation = {"episodes": args.episodes, "seed": args.seed, "scenario": "overtaking"}
    mobil = run(load_config(args.config, planner__agent="mobil", **evaluation), jobs=2)
    rows = []
    for name in args.variants.split(","):
        perception = {f"perception__{key}": value for key, value in VARIANTS[name].items()}
        config = load_config(args.config, train__steps=args.steps, **perception)
        model = trained(config, args.out / name)
        results = run(load_config(args.config, planner__model=model, **perception, **evaluation), jobs=2)
        difference = differences(results, mobil)["mean_speed"]
        summary = results.summary
        speed, collisions, changes = summary["mean_speed"], summary["collisions"], summary["lane_changes"]
        reach = "road" if VARIANTS[name].get("lanes") == "absolute" else VARIANTS[name]["lateral_reach"]
        rows.append(
            f"| {name} | {VARIANTS[name]['features']} | {reach} | {speed:.2f} | "
            f"{difference.value:+.2f} [{difference.low:+.2f}, {difference.high:+.2f}] | {collisions} | "
            f"{changes:.2f} |"
        )
    table = [
        f"{platform.machine()}, Python {platform.python_version()}; {args.steps} steps per variant",
        f"MOBIL: {mobil.summary['mean_speed']:.2f} m/s on overtaking seeds {args.seed}+ ({args.episodes})",
        "| variant | features | lanes each side | mean speed m/s | - mobil m/s (paired) | collisions "
        "| lane changes / ep |",
        "|---|---|---|---|---|---|---|",
        *rows,
    ]
    print("\n".join(table))
    write_text(args.out / "ablation.md", "\n".join(table) + "\n")


if __name__ == "__main__":
    main()
