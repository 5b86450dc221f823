"""`drivestack reproduce deepcars`: the table under the chosen rule sets, with a status line while
it trains, then results.md on the terminal."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console


def reproduce_and_report(out: Path, quick: bool, seed: int, variants: Sequence[str]) -> bool:
    """Reproduce the DeepCars table into `out` under each rule set of `variants` and print it; True
    when Ctrl-C cut it short (the rows finished are written)."""
    from stack.deepcars.reproduce import reproduce

    console = Console()
    with console.status("reproducing DeepCars") as status:
        reproduce(
            out,
            quick=quick,
            seed=seed,
            progress=lambda name: status.update(f"done: {name}"),
            variants=variants,
        )
    print((out / "results.md").read_text(), end="")
    interrupted = json.loads((out / "summary.json").read_text())["state"] == "interrupted"
    console.print(f"results: {out}" + (" (interrupted: the rows finished)" if interrupted else ""))
    return interrupted
