"""`drivestack safety`: the R157-style safety assessment. Every point of each chosen scenario grid
(`stack.sim.safety_scenarios`) is driven by the full stack and by the careful and competent
reference driver (`stack.assessment.safety_assessment`), here or over `jobs` processes or Ray tasks;
the results folder holds summary.json, safety.csv (one row per point) and one preventability map
per scenario type (`safety_<type>.png`). `--point` replays one point (with `--video`, as a GIF)."""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import numpy as np
from rich.console import Console
from tqdm import tqdm

from stack.apps.safety_report import plot_map, print_summary, summary
from stack.apps.view import shell_words, view_command_line
from stack.assessment.safety_assessment import Assessed, assess, drive_reference, drive_stack, point_name
from stack.loop.closed_loop import VIDEO_FRAME_TICKS
from stack.loop.recording import RECORDINGS
from stack.runtime.executors import completed
from stack.runtime.files import replacing, write_csv, write_json
from stack.runtime.interrupts import deferred
from stack.settings.run import RunConfig, write_config
from stack.sim.safety_scenarios import PARAMETERS, Point, ScenarioKind, grid


def replay_command(out: Path) -> str:
    """The command that replays a point of the run in `out` as a video (the stack its config.yaml
    resolved), with `{kind}` and `{point}` to fill."""
    config = shell_words(out / "config.yaml").replace("{", "{{").replace("}", "}}")
    return f"drivestack safety --config {config} --scenario {{kind}} --point {{point}} --video"


def assess_and_report(
    config: RunConfig,
    kinds: tuple[ScenarioKind, ...],
    quick: bool,
    out: Path,
    jobs: int,
    progress: bool,
    ray: str | None = None,
    record: bool = False,
) -> bool:
    """Assess every point of `kinds`' grids, write `out`, print the table and the replay commands
    of the failures; True when Ctrl-C cut it short (the points finished are written). With
    `record`, each failure point's drive is recorded in out/recordings, and the command that opens
    it is printed."""
    points = [point for kind in kinds for point in grid(kind, quick)]
    folder = out / RECORDINGS if record else None
    tasks = [(config, p, folder) if folder is not None else (config, p) for p in points]
    done: dict[int, Assessed] = {}
    interrupted = False
    with tqdm(total=len(points), unit="point", disable=not progress) as bar:
        try:
            for index, result in completed(assess, tasks, jobs, ray):
                done[index] = result
                bar.update(1)
                bar.set_postfix(failures=sum(r.outcome == "failure" for r in done.values()))
        except KeyboardInterrupt:
            if not done:
                raise
            interrupted = len(done) < len(points)  # a stop after the last point stops nothing
    results = [done[index] for index in sorted(done)]
    summaries = {
        kind: summary(kind, [r for r in results if r.point.kind == kind], replay_command(out))
        for kind in kinds
    }
    meta = {
        "agent": config.planner.agent,
        "controller": config.controller.type,
        "plant": config.sim.plant,
        "lanes": config.highway.lanes_count,
        "grid": "quick" if quick else "full",
        "interrupted": interrupted,
    }
    with deferred(interrupt_after=False):
        write_config(config, out / "config.yaml", "the resolved config of this safety assessment")
        write_json(out / "summary.json", {**meta, "scenarios": summaries})
        write_csv(out / "safety.csv", table_rows(results))
        for kind in (kind for kind in kinds if summaries[kind]["points"]):
            title = (
                f"{kind}: {config.planner.agent} + {config.controller.type}, {config.sim.plant} plant "
                "vs R157 careful & competent driver"
            )
            plot_map(kind, [r for r in results if r.point.kind == kind], title, out / f"safety_{kind}.png")
    print_summary(summaries)
    kept = [
        folder / f"{point_name(r.point)}.rrd"
        for r in results
        if folder is not None and r.outcome == "failure"
    ]
    for path in kept:
        if path.is_file():
            Console().print(
                f"failure: open its recording with  {view_command_line(path)}",
                highlight=False,
                markup=False,
                soft_wrap=True,
            )
    stopped = f" (interrupted: {len(results)} of {len(points)} points)" if interrupted else ""
    Console().print(f"results: {out}{stopped}")
    return interrupted


def table_rows(results: list[Assessed]) -> list[dict[str, object]]:
    """safety.csv's rows: every scenario's parameters as columns (empty where a type has none)."""
    names = list(dict.fromkeys(name for kind in PARAMETERS for name, _ in PARAMETERS[kind]))
    rows = []
    for result in results:
        row = result.row()
        rows.append({"scenario": row.pop("scenario")} | {n: row.pop(n, "") for n in names} | row)
    return rows


def replay(config: RunConfig, point: Point, video: bool, out: Path, record: bool = False) -> bool:
    """Drive one point with both drivers, print the outcome, and with `video` write the stack's
    drive as out/safety_<type>.gif, with `record` as a recording in out/recordings; False (never
    interrupted)."""
    frames: list[np.ndarray] | None = [] if video else None
    folder = out / RECORDINGS if record else None
    result = Assessed(point, drive_stack(config, point, frames, folder), drive_reference(config, point))
    with deferred(interrupt_after=False):
        write_config(config, out / "config.yaml", f"the resolved config; point {point.kind} {point.text}")
        write_json(out / "point.json", result.row())
        if frames:
            with replacing(out / f"safety_{point.kind}.gif") as path:
                # imageio's stub types the frames as list[ArrayLike], invariant: list[np.ndarray] is refused
                imageio.mimsave(path, frames, duration=1000 * VIDEO_FRAME_TICKS / 15, loop=0)  # type: ignore[arg-type]
    stack, reference = result.stack, result.reference
    Console().print(
        f"{point.kind} {point.text}: {result.outcome} (stack: {_collision(stack.collided)}, min gap "
        f"{stack.min_gap_m:.2f} m, min TTC {stack.min_ttc_s:.2f} s, peak decel {stack.peak_deceleration:.2f} "
        f"m/s²; reference driver: {_collision(reference.collided)})",
        highlight=False,
    )
    Console().print(f"results: {out}", highlight=False)
    if folder is not None:
        shown = view_command_line(folder / f"{point_name(point)}.rrd")
        Console().print(f"open it: {shown}", highlight=False, markup=False, soft_wrap=True)
    return False


def _collision(collided: bool) -> str:
    return "collision" if collided else "no collision"
