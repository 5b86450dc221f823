"""Writes an episode's recording (`stack.core.recording`) as a rerun `.rrd` file: the entities of
docs/recording.md, their styles and a default layout (the road following the ego, the controllers'
signals, the decisions' scores, the events). rerun is imported here only, when a file is written.

Timelines: `sim_time` (the simulation's time [s]), `tick` (control ticks from the episode's start,
0 at reset) and `decision` (decision points, from 0).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from records import Command, WorldState

APPLICATION_ID = "drivestack"
VIEW_AHEAD_M, VIEW_BEHIND_M = 150.0, 60.0
"""What the road view shows around the ego along the road [m]."""
ROAD_STEP_M = 5.0
"""Spacing of the points of the lane lines [m] (bends are drawn as polylines)."""
COLOURS = {
    "ego": (30, 110, 230),
    "leader": (240, 150, 20),
    "reacted": (220, 30, 30),
    "traffic": (120, 120, 120),
    "lines": (200, 200, 200),
    "edges": (60, 60, 60),
    "reference": (20, 190, 90),
    "grid": (230, 40, 200),
}
"""RGB per vehicle role and road element."""
WIDTHS = {"ego": -1.5, "leader": -1.5, "reacted": -1.5, "traffic": -1.0, "lines": -0.75, "edges": -1.5}
WIDTHS |= {"reference": -1.25, "grid": -1.0}
"""Line radius per role and road element in the viewer's UI points (rerun reads a negative radius
so): lines stay visible however far the view is zoomed out."""
SCORE_COLOURS = {Command.LEFT: (40, 120, 240), Command.STAY: (90, 90, 90), Command.RIGHT: (240, 120, 40)}
UNITS = {
    "ego/speed": "m/s",
    "ego/d": "m",
    "ego/d_reference": "m",
    "control/steering": "rad",
    "control/acceleration": "m/s²",
    "control/lateral_error": "m",
    "control/heading_error": "rad",
    "control/solve_time": "ms",
    "maneuver/lane": "lane",
    "maneuver/target_lane": "lane",
    "safety/ttc": "s",
    "safety/below_min_distance": "1 while below",
}


@dataclass
class Decision:
    """One decision point: when [s], the agent's command, what the safety layer let through
    (`filtered`), what the maneuver received (`applied`; None while a lane change ran), the agent's
    scores per command, and the occupied cells of the grid it saw as polygons [m]."""

    time: float
    command: Command
    filtered: Command | None
    applied: Command | None
    scores: np.ndarray | None
    score_name: str
    cells: list[np.ndarray]
    grid: np.ndarray

    @property
    def outcome(self) -> str:
        """What became of the command: permitted, masked, refused by the maneuver, or ignored."""
        if self.filtered is None:
            return "ignored: a lane change runs"
        if self.filtered is not self.command:
            return "masked by the safety layer"
        if self.applied is not self.command:
            return "refused by the maneuver (off the road or below its minimum speed)"
        return "permitted"


@dataclass
class Buffers:
    """Everything recorded so far, column by column (one entry per sample)."""

    time: list[float] = field(default_factory=list)
    series: dict[str, list[float]] = field(default_factory=dict)
    boxes: list[np.ndarray] = field(default_factory=list)
    roles: list[np.ndarray] = field(default_factory=list)
    shift: list[tuple[float, float]] = field(default_factory=list)
    """Per sample: the ego's x [m] and how far the road's reference line has moved in y [m] since
    the start (0 on a straight road): the road view follows both."""
    events: list[tuple[float, str, str]] = field(default_factory=list)
    phases: list[tuple[float, str]] = field(default_factory=list)
    paths: list[tuple[float, np.ndarray]] = field(default_factory=list)
    decisions: list[Decision] = field(default_factory=list)

    def add(self, name: str, value: float) -> None:
        self.series.setdefault(name, []).append(value)


def quiet_rerun() -> Any:
    """The rerun module, imported with its anonymous usage data off: rerun 0.41 reads no switch of
    its own in the SDK (it writes files without any), and its viewer skips analytics when `CI` is
    set (`re_analytics`), which `stack.apps.view` sets for the viewer it starts."""
    os.environ.pop("FORCE_RERUN_ANALYTICS", None)
    import rerun

    return rerun


def write_recording(
    path: Path, title: str, first: WorldState, dt: float, buffers: Buffers, s_range: list[float]
) -> None:
    """The recording in `buffers` as `path`, written under a temporary name and renamed."""
    rr = quiet_rerun()
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".part")
    recording = rr.RecordingStream(APPLICATION_ID, recording_id=path.stem + "-" + os.urandom(4).hex())
    recording.set_log_time_enabled(False)
    recording.set_log_tick_enabled(False)
    recording.save(partial, default_blueprint=blueprint(rr, first))
    try:
        recording.send_recording_name(f"{path.stem}: {title}")
        recording.log("description", rr.TextDocument(title), static=True)
        _road(rr, recording, first, s_range)
        _ticks(rr, recording, buffers)
        _decisions(rr, recording, buffers)
        _events(rr, recording, buffers)
        recording.flush()
    finally:
        recording.disconnect()
    os.replace(partial, path)


def blueprint(rr: Any, world: WorldState) -> Any:
    """The default layout: the road view (`world`'s road, around the ego) beside the time series
    and the events."""
    rrb = rr.blueprint
    half, offsets = world.lane_width / 2, world.lane_offsets
    across = [float(offsets.min()) - half - 8.0, float(offsets.max()) + half + 8.0]
    bounds = rrb.VisualBounds2D(x_range=[-VIEW_BEHIND_M, VIEW_AHEAD_M], y_range=across)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(origin="scene", name="road (follows the ego)", visual_bounds=bounds),
                rrb.TextLogView(origin="events", name="events and decisions"),
                row_shares=[2, 1],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="ego", name="ego"),
                rrb.TimeSeriesView(origin="control", name="controller"),
                rrb.TimeSeriesView(origin="decision/scores", name="decision scores"),
                rrb.TimeSeriesView(origin="safety", name="safety"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def _strips(rr: Any, polygons: np.ndarray) -> Any:
    """(strips, points, 2) float32 as rerun's LineStrip2D arrow array, built in one piece."""
    import pyarrow as pa  # type: ignore[import-untyped]

    kind = rr.components.LineStrip2DBatch._ARROW_DATATYPE
    count, points = polygons.shape[0], polygons.shape[1] if polygons.ndim == 3 else 0
    values = pa.array(np.ascontiguousarray(polygons, dtype=np.float32).reshape(-1), type=pa.float32())
    offsets = pa.array(np.arange(0, count * points + 1, max(points, 1), dtype=np.int32)[: count + 1])
    return pa.ListArray.from_arrays(
        offsets, pa.FixedSizeListArray.from_arrays(values, type=kind.value_type), type=kind
    )


def _road(rr: Any, recording: Any, world: WorldState, s_range: list[float]) -> None:
    """Lane lines and road edges (static), along the stretch of road the vehicles covered."""
    lane = world.lanes[0]
    start, end = s_range[0] - VIEW_AHEAD_M, s_range[1] + VIEW_AHEAD_M
    s = np.arange(start, end + ROAD_STEP_M, ROAD_STEP_M)
    half, offsets = world.lane_width / 2, sorted(float(o) for o in world.lane_offsets)
    boundaries = [offsets[0] - half] + [o + half for o in offsets]
    lines = [np.array([lane.position(float(x), b) for x in s], dtype=np.float32) for b in boundaries]
    for name, strips in (("edges", [lines[0], lines[-1]]), ("lines", lines[1:-1])):
        recording.log(
            f"scene/world/road/{name}",
            rr.LineStrips2D(strips, colors=COLOURS[name], radii=WIDTHS[name]),
            static=True,
        )


def _ticks(rr: Any, recording: Any, buffers: Buffers) -> None:
    """Per tick: the view's shift, every vehicle's box by role, the reference paths and the series."""
    times = np.array(buffers.time)
    index = [rr.TimeColumn("sim_time", duration=times), rr.TimeColumn("tick", sequence=np.arange(len(times)))]
    shift = np.zeros((len(times), 3))
    shift[:, :2] = -np.array(buffers.shift)
    recording.send_columns("scene/world", index, rr.Transform3D.columns(translation=shift))
    boxes, roles = np.concatenate(buffers.boxes), np.concatenate(buffers.roles)
    for number, role in enumerate(("ego", "leader", "reacted", "traffic")):
        chosen = roles == number
        counts = [int(np.count_nonzero(r == number)) for r in buffers.roles]
        path = f"scene/world/vehicles/{role}"
        recording.log(
            path, rr.LineStrips2D.from_fields(colors=COLOURS[role], radii=WIDTHS[role]), static=True
        )
        strips = rr.LineStrips2D.columns(strips=_strips(rr, boxes[chosen])).partition(counts)
        recording.send_columns(path, index, strips)
    tick_index = [
        rr.TimeColumn("sim_time", duration=times[1:]),
        rr.TimeColumn("tick", sequence=np.arange(1, len(times))),
    ]
    for name, values in buffers.series.items():
        recording.log(name, rr.SeriesLines(names=f"{name.split('/')[-1]} [{UNITS[name]}]"), static=True)
        columns = index if len(values) == len(times) else tick_index
        recording.send_columns(name, columns, rr.Scalars.columns(scalars=np.array(values, dtype=float)))
    recording.log(
        "scene/world/reference",
        rr.LineStrips2D.from_fields(colors=COLOURS["reference"], radii=WIDTHS["reference"]),
        static=True,
    )
    for time, points in buffers.paths:
        recording.set_time("sim_time", duration=time)
        recording.log("scene/world/reference", rr.LineStrips2D([points]))


def _decisions(rr: Any, recording: Any, buffers: Buffers) -> None:
    """Per decision point: the command, what the safety layer made of it, the scores, the grid."""
    for name in ("command", "applied"):
        recording.log(
            f"decision/{name}", rr.SeriesPoints(names=f"{name} (lane shift: -1 left, +1 right)"), static=True
        )
    for command in Command:
        recording.log(
            f"decision/scores/{command.name}",
            rr.SeriesPoints(names=command.name, colors=SCORE_COLOURS[command]),
            static=True,
        )
    recording.log(
        "scene/world/grid",
        rr.LineStrips2D.from_fields(colors=COLOURS["grid"], radii=WIDTHS["grid"]),
        static=True,
    )
    for number, decision in enumerate(buffers.decisions):
        recording.set_time("sim_time", duration=decision.time)
        recording.set_time("decision", sequence=number)
        recording.log("decision/command", rr.Scalars(decision.command.lane_shift))
        applied = decision.applied.lane_shift if decision.applied is not None else np.nan
        recording.log("decision/applied", rr.Scalars(applied))
        text = f"decision {number}: {decision.command.name}, {decision.outcome}"
        if decision.scores is not None:
            text += f"; {decision.score_name}: " + ", ".join(
                f"{command.name} {value:.3g}"
                for command, value in zip(Command, decision.scores, strict=False)
            )
            for command, value in zip(Command, decision.scores, strict=False):
                recording.log(f"decision/scores/{command.name}", rr.Scalars(float(value)))
        level = "INFO" if decision.outcome == "permitted" else "WARN"
        recording.log("events/decisions", rr.TextLog(text, level=level))
        recording.log(
            "decision/grid", rr.Tensor(decision.grid, dim_names=["row (lane)", "cell (along the road)"])
        )
        recording.log("scene/world/grid", rr.LineStrips2D(decision.cells))
    recording.reset_time()


def _events(rr: Any, recording: Any, buffers: Buffers) -> None:
    """Safety events and maneuver phases as text entries on the timeline."""
    for entity, entries in (
        ("events/safety", buffers.events),
        ("events/maneuver", [(time, phase, "INFO") for time, phase in buffers.phases]),
    ):
        if entries:
            recording.send_columns(
                entity,
                [rr.TimeColumn("sim_time", duration=[time for time, _, _ in entries])],
                rr.TextLog.columns(
                    text=[text for _, text, _ in entries], level=[level for _, _, level in entries]
                ),
            )
