"""Markdown table of a `drivestack track` run (left and right averaged per row).

.venv/bin/drivestack track --out runs/track && .venv/bin/python benchmarks/tracking_table.py runs/track
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path


def main() -> None:
    records = json.loads((Path(sys.argv[1]) / "tracking.json").read_text())
    groups = defaultdict(list)
    for r in records:
        groups[(r["road"], r["plant"], r["controller"], r["speed"])].append(r)
    print(
        "| road | plant | controller | speed m/s | duration s | overshoot cm | RMS cm | max cm "
        "| peak a_y m/s² | peak jerk m/s³ | solve p50 / p95 ms | fallbacks |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (road, plant, controller, speed), rows in groups.items():

        def mean(key, rows=rows):
            values = [r[key] for r in rows if r[key] is not None]
            return sum(values) / len(values) if values else float("nan")

        print(
            f"| {road} | {plant} | {controller} | {speed:g} | {mean('duration_s'):.2f} | "
            f"{100 * max(r['overshoot_m'] for r in rows):.1f} | {100 * mean('rms_error_m'):.2f} | "
            f"{100 * max(r['max_error_m'] for r in rows):.1f} | "
            f"{max(r['peak_lat_accel'] for r in rows):.2f} | "
            f"{max(r['peak_lat_jerk'] for r in rows):.2f} | {mean('solve_ms_p50'):.2f} / "
            f"{max(r['solve_ms_p95'] for r in rows):.2f} | {sum(r['fallbacks'] for r in rows)} |"
        )


if __name__ == "__main__":
    main()
