"""Writes an episode's recording (`stack.loop.recording`) as a rerun `.rrd` file: the entities of
docs/recording.md, their styles and a default layout (the road following the ego, the controllers'
signals, the decisions' scores, the events). rerun is imported here only, when a file is written.

Timelines: `sim_time` (the simulation's time [s]), `tick` (control ticks from the episode's start,
0 at reset) and `decision` (decision points, from 0).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from perception.grid import OccupancyGrid
from records import Command, WorldState
from stack.rrd.recording_geometry import box_corners, grid_cells, lane_points
from stack.runtime.files import make_folder

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
    "detections": (250, 200, 0),
    "tracks": (0, 200, 220),
}
"""RGB per vehicle role and road element."""
ROLES = ("ego", "leader", "reacted", "traffic")
"""Vehicle roles, each its own entity: the ego, the leaders its cruise keeps a gap to, the vehicles
the safety layer or emergency braking reacted to, everyone else (the first role that fits)."""
WIDTHS = {"ego": -1.5, "leader": -1.5, "reacted": -1.5, "traffic": -1.0, "lines": -0.75, "edges": -1.5}
WIDTHS |= {"reference": -1.25, "grid": -1.0, "detections": -2.0, "tracks": -3.5}
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
    scores per command (in `score_name`'s unit), the world then and the grid the agent saw."""

    time: float
    command: Command
    filtered: Command | None
    applied: Command | None
    scores: np.ndarray | None
    score_name: str
    world: WorldState
    grid: OccupancyGrid | None

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


class Frame(NamedTuple):
    """What a recording keeps of one world: its time [s], and per vehicle (row 0 the ego) the id,
    centre [m], heading [rad], length and width [m] and position along the road `s` [m]. The
    arrays are the world's own (a record's arrays never change), so keeping them copies nothing."""

    time: float
    ids: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    s: np.ndarray

    @classmethod
    def of(cls, world: WorldState) -> Frame:
        return cls(world.time, world.ids, world.position, world.heading, world.length, world.width, world.s)


@dataclass
class Buffers:
    """Everything recorded so far, column by column (one entry per sample)."""

    first: WorldState | None = None
    """The world at the start (its road is drawn)."""
    frames: list[Frame] = field(default_factory=list)
    """The vehicles at the start and after every tick."""
    marked: list[tuple[tuple[int, ...], tuple[int, ...]]] = field(default_factory=list)
    """Per world: the ids of the ego's leaders and of the vehicles the safety layer or emergency
    braking reacted to."""
    series: dict[str, list[float]] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)
    phases: list[tuple[float, str]] = field(default_factory=list)
    paths: list[tuple[float, np.ndarray]] = field(default_factory=list)
    decisions: list[Decision] = field(default_factory=list)
    sensed: list[tuple[float, np.ndarray, np.ndarray]] = field(default_factory=list)
    """Per tick seen through a sensor: its time [s], the detections' and the confirmed tracks'
    centres (points, 2) [m] (no tracks when the tracker is off)."""

    def add(self, name: str, value: float) -> None:
        self.series.setdefault(name, []).append(value)


def quiet_rerun() -> Any:
    """The rerun module, imported with its anonymous usage data off: rerun 0.41 reads no switch of
    its own in the SDK (it writes files without any), and its viewer skips analytics when `CI` is
    set (`re_analytics`), which `stack.apps.view` sets for the viewer it starts."""
    os.environ.pop("FORCE_RERUN_ANALYTICS", None)
    import rerun

    return rerun


def write_recording(path: Path, title: str, buffers: Buffers) -> None:
    """The recording in `buffers` as `path`, written under a temporary name and renamed."""
    rr = quiet_rerun()
    first = buffers.first
    if first is None:
        raise ValueError("a recording starts with its first world")
    make_folder(path.parent)
    partial = path.with_name(path.name + ".part")
    recording = rr.RecordingStream(APPLICATION_ID, recording_id=path.stem + "-" + os.urandom(4).hex())
    recording.set_log_time_enabled(False)
    recording.set_log_tick_enabled(False)
    recording.save(partial, default_blueprint=blueprint(rr, first))
    try:
        recording.send_recording_name(f"{path.stem}: {title}")
        recording.log("description", rr.TextDocument(title), static=True)
        _road(rr, recording, first, buffers.frames)
        _ticks(rr, recording, first, buffers)
        _sensed(rr, recording, buffers)
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


def _road(rr: Any, recording: Any, world: WorldState, frames: list[Frame]) -> None:
    """Lane lines and road edges (static) of `world`'s road, along the stretch the vehicles covered."""
    covered = np.concatenate([f.s for f in frames[:: max(1, len(frames) // 50)] + frames[-1:]])
    s = np.arange(covered.min() - VIEW_AHEAD_M, covered.max() + VIEW_AHEAD_M + ROAD_STEP_M, ROAD_STEP_M)
    half, offsets = world.lane_width / 2, sorted(float(o) for o in world.lane_offsets)
    boundaries = [offsets[0] - half] + [o + half for o in offsets]
    lines = [lane_points(world.lanes[0], s, np.full(len(s), b)).astype(np.float32) for b in boundaries]
    for name, strips in (("edges", [lines[0], lines[-1]]), ("lines", lines[1:-1])):
        recording.log(
            f"scene/world/road/{name}",
            rr.LineStrips2D(strips, colors=COLOURS[name], radii=WIDTHS[name]),
            static=True,
        )


def _ticks(rr: Any, recording: Any, first: WorldState, buffers: Buffers) -> None:
    """Per tick: the view's shift, every vehicle's box by role, the reference paths and the series."""
    worlds = buffers.frames
    times = np.array([world.time for world in worlds])
    index = [rr.TimeColumn("sim_time", duration=times), rr.TimeColumn("tick", sequence=np.arange(len(times)))]
    shift = _view_shift(first, worlds)
    recording.send_columns("scene/world", index, rr.Transform3D.columns(translation=shift))
    counts = np.array([len(world.ids) for world in worlds])
    boxes = box_corners(
        np.concatenate([world.position for world in worlds]),
        np.concatenate([world.heading for world in worlds]),
        np.concatenate([world.length for world in worlds]),
        np.concatenate([world.width for world in worlds]),
    )
    owner = np.repeat(np.arange(len(worlds)), counts)
    roles = _roles(owner, np.concatenate([world.ids for world in worlds]), buffers.marked)
    for number, role in enumerate(ROLES):
        chosen = roles == number
        path = f"scene/world/vehicles/{role}"
        recording.log(
            path, rr.LineStrips2D.from_fields(colors=COLOURS[role], radii=WIDTHS[role]), static=True
        )
        per_world = np.bincount(owner[chosen], minlength=len(worlds))
        strips = rr.LineStrips2D.columns(strips=_strips(rr, boxes[chosen])).partition(per_world)
        recording.send_columns(path, index, strips)
    tick_index = [
        rr.TimeColumn("sim_time", duration=times[1:]),
        rr.TimeColumn("tick", sequence=np.arange(1, len(times))),
    ]
    for name, values in buffers.series.items():
        recording.log(name, rr.SeriesLines(names=f"{name.split('/')[-1]} [{UNITS[name]}]"), static=True)
        columns = index if len(values) == len(times) else tick_index
        recording.send_columns(name, columns, rr.Scalars.columns(scalars=np.array(values, dtype=float)))
    style = rr.LineStrips2D.from_fields(colors=COLOURS["reference"], radii=WIDTHS["reference"])
    recording.log("scene/world/reference", style, static=True)
    if buffers.paths:
        paths = np.stack([points for _, points in buffers.paths])
        when = [rr.TimeColumn("sim_time", duration=[time for time, _ in buffers.paths])]
        strips = rr.LineStrips2D.columns(strips=_strips(rr, paths)).partition(np.ones(len(paths), dtype=int))
        recording.send_columns("scene/world/reference", when, strips)


def _sensed(rr: Any, recording: Any, buffers: Buffers) -> None:
    """Per tick seen through a sensor: the detections and the confirmed tracks, as points."""
    if not buffers.sensed:
        return
    when = [rr.TimeColumn("sim_time", duration=[time for time, _, _ in buffers.sensed])]
    for name, points in (
        ("detections", [detected for _, detected, _ in buffers.sensed]),
        ("tracks", [tracked for _, _, tracked in buffers.sensed]),
    ):
        path = f"scene/world/{name}"
        recording.log(path, rr.Points2D.from_fields(colors=COLOURS[name], radii=WIDTHS[name]), static=True)
        positions = np.concatenate(points).astype(np.float32) if points else np.zeros((0, 2), np.float32)
        counts = np.array([len(p) for p in points], dtype=np.int64)
        recording.send_columns(path, when, rr.Points2D.columns(positions=positions).partition(counts))


def _roles(
    owner: np.ndarray, ids: np.ndarray, marked: list[tuple[tuple[int, ...], tuple[int, ...]]]
) -> np.ndarray:
    """Each box's role (index in `ROLES`): `owner` is the world of each box, `ids` its vehicle,
    `marked` per world the leaders and the vehicles reacted to (reacted wins); a world's first box is
    the ego."""
    roles = np.full(len(ids), ROLES.index("traffic"), dtype=np.int8)
    span = int(ids.max()) + 1 if len(ids) else 1
    key = owner.astype(np.int64) * span + ids
    for role, column in (("leader", 0), ("reacted", 1)):
        wanted = [world * span + vehicle for world, marks in enumerate(marked) for vehicle in marks[column]]
        if wanted:
            roles[np.isin(key, np.array(wanted, dtype=np.int64))] = ROLES.index(role)
    roles[np.flatnonzero(np.diff(owner, prepend=-1))] = ROLES.index("ego")
    return roles


def _view_shift(first: WorldState, worlds: list[Frame]) -> np.ndarray:
    """Per world, the translation [m] that keeps the road view on the ego: back by the ego's x,
    and by how far the road's reference line has moved in y since the start (0 on a straight
    road), so the view follows the road through a bend and the ego's lane changes show."""
    shift = np.zeros((len(worlds), 3))
    shift[:, 0] = [-float(world.position[0, 0]) for world in worlds]
    lane, s = first.lanes[0], np.array([float(world.s[0]) for world in worlds])
    road_y = lane_points(lane, s, np.zeros(len(s)))[:, 1]
    shift[:, 1] = -(road_y - road_y[0])
    return shift


def _decisions(rr: Any, recording: Any, buffers: Buffers) -> None:
    """Per decision point: the command, what the safety layer made of it, the scores, the grid."""
    decisions = buffers.decisions
    for name in ("command", "applied"):
        style = rr.SeriesPoints(names=f"{name} (lane shift: -1 left, +1 right)")
        recording.log(f"decision/{name}", style, static=True)
    for command in Command:
        style = rr.SeriesPoints(names=command.name, colors=SCORE_COLOURS[command])
        recording.log(f"decision/scores/{command.name}", style, static=True)
    style = rr.LineStrips2D.from_fields(colors=COLOURS["grid"], radii=WIDTHS["grid"])
    recording.log("scene/world/grid", style, static=True)
    if not decisions:
        return
    index = [
        rr.TimeColumn("sim_time", duration=[decision.time for decision in decisions]),
        rr.TimeColumn("decision", sequence=np.arange(len(decisions))),
    ]
    commands = np.array([decision.command.lane_shift for decision in decisions], dtype=float)
    applied = [
        decision.applied.lane_shift if decision.applied is not None else np.nan for decision in decisions
    ]
    recording.send_columns("decision/command", index, rr.Scalars.columns(scalars=commands))
    recording.send_columns(
        "decision/applied", index, rr.Scalars.columns(scalars=np.array(applied, dtype=float))
    )
    scores = np.array(
        [
            d.scores[: len(Command)] if d.scores is not None else np.full(len(Command), np.nan)
            for d in decisions
        ]
    )
    for command in Command:
        column = rr.Scalars.columns(scalars=scores[:, command])
        recording.send_columns(f"decision/scores/{command.name}", index, column)
    texts = [_decision_text(number, decision) for number, decision in enumerate(decisions)]
    levels = ["INFO" if decision.outcome == "permitted" else "WARN" for decision in decisions]
    recording.send_columns("events/decisions", index, rr.TextLog.columns(text=texts, level=levels))
    cells = [grid_cells(d.world, d.grid) if d.grid is not None else np.zeros((0, 5, 2)) for d in decisions]
    polygons = _strips(rr, np.concatenate(cells)) if cells else None
    counts = np.array([len(c) for c in cells])
    recording.send_columns(
        "scene/world/grid", index, rr.LineStrips2D.columns(strips=polygons).partition(counts)
    )


def _decision_text(number: int, decision: Decision) -> str:
    """One line for the events: the command, what became of it, the agent's scores."""
    text = f"decision {number}: {decision.command.name}, {decision.outcome}"
    if decision.scores is not None:
        rated = zip(Command, decision.scores, strict=False)
        text += f"; {decision.score_name}: " + ", ".join(
            f"{command.name} {value:.3g}" for command, value in rated
        )
    return text


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
