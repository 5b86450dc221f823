"""Markdown table of a `drivestack track` run: per controller, road, plant and speed, the worst of
the left and right change (the table `drivestack track` prints).

.venv/bin/drivestack track --out runs/track && .venv/bin/python benchmarks/tracking_table.py runs/track
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from stack.apps.track_report import markdown_table


def main() -> None:
    print(markdown_table(json.loads((Path(sys.argv[1]) / "tracking.json").read_text())), end="")


if __name__ == "__main__":
    main()
