"""`drivestack track`: single lane changes on an empty highway-env road, one record per maneuver.

For every road (straight; bends of 1000 m and, up to 25 m/s, 500 m radius), plant (highway-env's
kinematic bicycle; its dynamic bicycle with tyre slip), controller, speed and direction, the closed
loop of `drivestack run` drives `stack.sim.empty_road`: 1 s of lane keeping, then a quintic lane
change of `duration` seconds from the middle lane's centre to the neighbour's, then lane keeping
to 3 s after its end. `builtin` is highway-env's own ControlledVehicle lane change; `all` is every
built-in controller and every one installed packages register (entry points
`drivestack.controllers`); plug-in classes (`module.path:Class`, `file.py:Class`) join by name.

Metrics (`stack.loop.metrics.tracking`, defined in docs/architecture.md): lateral RMS / max error to
the reference, overshoot, duration, peak |a_y| and lateral jerk, controller time per tick p50 / p95,
MPC fallbacks.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from contextlib import closing
from dataclasses import asdict
from pathlib import Path

from pydantic import ValidationError
from rich.console import Console
from tqdm import tqdm

from common.plugins import CONTROLLER_GROUP, entry_points, label
from controllers.config import ControllerConfig
from controllers.tracker import make_controller
from records import CONTROLLER_NAMES, PLANTS, Command, PlantName
from stack.apps.resume import code_files, edited_file, warn
from stack.apps.track_record import TrackedLaneChange
from stack.apps.track_report import plot_maneuvers, print_tracking, speed_label
from stack.apps.view import view_command_line
from stack.loop.closed_loop import ClosedLoop
from stack.loop.metrics import Tracking, tracking
from stack.loop.recording import RECORDINGS, episode_recording
from stack.results.episode_measures import lateral_series
from stack.runtime.executors import completed
from stack.runtime.files import write_json
from stack.runtime.interrupts import deferred
from stack.settings.run import RunConfig, write_config
from stack.sim.empty_road import BuiltinDriver, EmptyRoad, PlantKind, RoadKind

TRACK_CONTROLLERS: tuple[str, ...] = (*CONTROLLER_NAMES, "builtin")
CONTROLLER_DESCRIPTIONS: dict[str, str] = {
    "pid": "cascaded lateral PID with model-inverting feedforward (the default)",
    "mpc": "joint steering + acceleration MPC on the bicycle model (CasADi), PID fallback",
    "pure-pursuit": "pure pursuit: the arc to a goal point 0.4 s ahead on the reference, no feedforward",
    "stanley": "Stanley: front-axle cross-track and heading errors, curvature feedforward",
    "lqr": "LQR on the lateral error dynamics (python-control dlqr), speed-scheduled, feedforward",
}
"""One line per built-in controller (`drivestack controllers`); each uses the adaptive cruise."""
ROADS: tuple[RoadKind, ...] = ("straight", "bend-1000", "bend-500")
TOP_SPEED: dict[RoadKind, float] = {"bend-500": 25.0}
"""Fastest maneuver on a road [m/s]: the 500 m bend's lateral acceleration is 1.25 m/s² at 25 m/s
before any lane change (and 2.45 at 35, beyond the comfort bound)."""
LEAD_IN_S = 1.0
SETTLE_S = 3.0
MAX_CHANGE_S = 60.0
"""The longest a lane change is followed [s] (one slowed down by a braking car takes longer than planned)."""
Speeds = tuple[float, float]
"""(speed at the start, the cruise's set speed) [m/s]; equal for a maneuver at constant speed."""


def controller_names(value: str) -> list[str]:
    """The controllers a comma-separated `--controller` value names, `all` expanded to every built-in
    and installed one, plug-in files made absolute; ValueError (one line) for an unknown name."""
    names: list[str] = []
    for name in value.split(","):
        if name == "all":
            names += [*TRACK_CONTROLLERS, *entry_points(CONTROLLER_GROUP)]
        elif name == "builtin":
            names.append(name)
        elif name:
            try:
                config = ControllerConfig(type=name)
            except ValidationError as error:
                raise ValueError(error.errors()[0]["msg"].removeprefix("Value error, ")) from None
            if config.type not in CONTROLLER_NAMES:
                make_controller(config, 1 / 15)
            names.append(config.type)
    return list(dict.fromkeys(names))


def controller_configs(controllers: list[str], config: RunConfig) -> list[RunConfig]:
    """`config` with each of `controllers` (but highway-env's `builtin`): the configs whose plug-in
    files `stack.apps.resume.code_digests` finds."""
    return [
        config.model_copy(update={"controller": config.controller.model_copy(update={"type": name})})
        for name in controllers
        if name != "builtin"
    ]


def warn_of_edited_plug_ins(controllers: list[str], config: RunConfig, out: Path) -> None:
    """One warning line naming a controller plug-in's file that was edited since the maneuvers in
    `out` (a `track` of the same arguments) were measured: none of them is kept, every maneuver
    is measured again with the edited file."""
    if (edited := edited_file(controller_configs(controllers, config), out)) is not None:
        warn(f"{edited} was edited since the maneuvers in this folder were measured; all are measured again")


def run_maneuver(
    controller_name: str,
    config: ControllerConfig,
    road_kind: RoadKind,
    plant: PlantKind,
    speeds: float | Speeds,
    direction: str,
    duration: float,
    dt: float,
    record: Path | None = None,
) -> TrackedLaneChange:
    """One lane change to the `direction` ("left" or "right") at `speeds` [m/s], or starting at
    `speeds[0]` with the cruise set to `speeds[1]`, in the closed loop: lane keeping for LEAD_IN_S,
    the change (however long the car's speed makes it), lane keeping for SETTLE_S. With `record`
    (a folder), the maneuver is recorded there (`maneuver_name`.rrd)."""
    speed, end_speed = speeds if isinstance(speeds, tuple) else (speeds, speeds)
    builtin = controller_name == "builtin"
    road = EmptyRoad(road_kind, "builtin" if builtin else plant, speed, dt)
    controller = config.model_copy(
        update={"type": "pid" if builtin else controller_name, "set_speed_mps": end_speed}
    )
    run_config = RunConfig.model_validate(
        {
            "highway": {"simulation_frequency": round(1 / dt)},
            "sim": {"plant": "kinematic" if builtin else plant},
            "control_rate_hz": round(1 / dt),
            "controller": controller.model_copy(update={"lane_change_duration_s": duration}),
        }
    )
    name = maneuver_name(controller_name, road_kind, plant, (speed, end_speed), direction)
    recording = episode_recording(run_config, record, name, 0)
    given = BuiltinDriver(road) if builtin else None
    loop = ClosedLoop(run_config, road, controller=given, recording=recording)
    loop.reset(seed=0)
    command = Command.LEFT if direction == "left" else Command.RIGHT
    planned = loop.start_lane_change(command, at_time=LEAD_IN_S)
    changing = duration if planned is None else planned
    loop.act(Command.STAY, ticks=round((LEAD_IN_S + changing) / dt))
    while loop.changing_lane and loop.world.time < LEAD_IN_S + MAX_CHANGE_S:
        loop.act(Command.STAY, ticks=1)
    loop.act(Command.STAY, ticks=round(SETTLE_S / dt))
    if recording is not None:
        recording.close()
    traces, solves = loop.traces(), loop.solve_statistics()
    time, d = traces.time[:-1], traces.d[:-1]
    heading, speed_trace, d_reference = traces.heading[:-1], traces.speed[:-1], traces.d_reference
    metrics: Tracking = tracking(time, d, d_reference, heading, speed_trace, dt)
    lateral_acceleration, jerk = lateral_series(heading, speed_trace, dt)
    return TrackedLaneChange(
        controller=label(controller_name),
        road=road_kind,
        plant=plant,
        speed=speed,
        end_speed=end_speed,
        direction=direction,
        **asdict(metrics),
        solve_ms_p50=solves.p50_ms,
        solve_ms_p95=solves.p95_ms,
        fallbacks=solves.fallbacks,
        started=planned is not None,
        trace={
            "time": time.tolist(),
            "d": (d - d[0]).tolist(),
            "d_ref": (d_reference - d[0]).tolist(),
            "steering": traces.steering.tolist(),
            "lat_accel": [0.0, *lateral_acceleration.tolist()],
            "lat_jerk": [0.0, 0.0, *jerk.tolist()],
        },
    )


def maneuver_name(controller: str, road: RoadKind, plant: str, speeds: Speeds, direction: str) -> str:
    """A maneuver's file name (no suffix): controller, road, plant, speed [m/s], direction."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", label(controller)).strip("._")
    return f"{safe}-{road}-{plant}-{speed_label(speeds)}mps-{direction}"


def _run_maneuver(arguments: tuple) -> TrackedLaneChange:
    """`run_maneuver` on one tuple of arguments (a task for `completed`)."""
    return run_maneuver(*arguments)


def track_and_report(
    controllers: list[str],
    speeds: list[Speeds],
    config: RunConfig,
    out: Path,
    progress: bool,
    plants: tuple[PlantName, ...] = PLANTS,
    ray: str | None = None,
    record: bool = False,
) -> bool:
    """Every maneuver (here, or as Ray tasks at address `ray`) with a progress bar, then the table
    (before the files: a folder that cannot be written loses no figure measured), the files and
    where they are; True when Ctrl-C cut it short (the maneuvers finished are written; none
    finished: KeyboardInterrupt). With `record`, each maneuver's recording goes to out/recordings."""
    builtin_runs = 1 if "kinematic" in plants else 0
    total = (
        sum(len(speeds_on(road, speeds)) for road in ROADS)
        * 2
        * sum(builtin_runs if n == "builtin" else len(plants) for n in controllers)
    )
    with tqdm(total=total, unit="maneuver", disable=not progress) as bar:
        maneuvers = measure(
            controllers,
            speeds,
            config.controller.lane_change_duration_s,
            config.controller,
            config.dt,
            plants=plants,
            progress=lambda: bar.update(1),
            ray=ray,
            record=out / RECORDINGS if record else None,
        )
    print_tracking(maneuvers)
    with deferred(interrupt_after=False):
        write_tracking(maneuvers, out, ROADS, plants, speeds)
        comment = "the resolved config of this run (its controller section)"
        write_config(
            config, out / "config.yaml", comment + code_files(controller_configs(controllers, config))
        )
    interrupted = len(maneuvers) < total
    stopped = f" (interrupted: the {len(maneuvers)} of {total} maneuvers finished)"
    Console().print(f"results: {out}" + (stopped if interrupted else ""))
    if record:
        hint = f"{view_command_line(out / RECORDINGS)}/NAME.rrd"
        Console().print(f"replay a maneuver: {hint}", highlight=False, markup=False, soft_wrap=True)
    return interrupted


def measure(
    controllers: list[str],
    speeds: list[Speeds],
    duration: float,
    config: ControllerConfig,
    dt: float = 1 / 15,
    roads: tuple[RoadKind, ...] = ROADS,
    plants: tuple[PlantName, ...] = PLANTS,
    progress: Callable[[], object] | None = None,
    ray: str | None = None,
    record: Path | None = None,
) -> list[TrackedLaneChange]:
    """All maneuvers, in a fixed order whatever ran them (here, or Ray tasks at address `ray`).
    Ctrl-C keeps the maneuvers finished (none: it is raised). `record`: the folder each maneuver
    writes its recording into."""
    chosen = [
        (name, config, road_kind, plant, speed, direction, duration, dt, record)
        for road_kind in roads
        for plant in plants
        for name in controllers
        if not (name == "builtin" and plant == "dynamic")
        for speed in speeds_on(road_kind, speeds)
        for direction in ("left", "right")
    ]
    done: dict[int, TrackedLaneChange] = {}
    try:
        with closing(completed(_run_maneuver, chosen, ray=ray)) as maneuvers_coming:
            for index, maneuver in maneuvers_coming:
                done[index] = maneuver
                if progress:
                    progress()
    except KeyboardInterrupt:
        if not done:
            raise
    return [done[index] for index in sorted(done)]


def write_tracking(
    maneuvers: list[TrackedLaneChange],
    out: Path,
    roads: tuple[RoadKind, ...],
    plants: tuple[PlantName, ...],
    speeds: list[Speeds],
) -> None:
    """out/tracking.json and one figure per road, plant and speed that has a maneuver."""
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "tracking.json", [m.record() for m in maneuvers])
    for road_kind in roads:
        for plant in plants:
            for speed in speeds_on(road_kind, speeds):
                shown = [
                    m
                    for m in maneuvers
                    if (m.road, m.plant, (m.speed, m.end_speed), m.direction)
                    == (road_kind, plant, speed, "left")
                ]
                plot_maneuvers(shown, out / f"tracking_{road_kind}_{plant}_{speed_label(speed)}mps.png")


def speeds_on(road: RoadKind, speeds: list[Speeds]) -> list[Speeds]:
    """The `speeds` a road is driven at (up to its `TOP_SPEED` [m/s])."""
    return [speed for speed in speeds if max(speed) <= TOP_SPEED.get(road, float("inf"))]


def parse_speeds(text: str) -> list[Speeds]:
    """`--speeds` entries, each `V` (constant) or `A-B` (from A with the cruise set to B) [m/s];
    ValueError (one line) for anything else or a speed outside (0, 40]."""
    found: list[Speeds] = []
    for entry in text.split(","):
        parts = entry.split("-")
        try:
            values = [float(part) for part in parts]
        except ValueError:
            raise ValueError(f"expected V or A-B in m/s, comma-separated, got {entry!r}") from None
        if len(values) not in (1, 2) or not all(0 < v <= 40 for v in values):
            raise ValueError(f"every speed must be V or A-B with speeds in (0, 40] m/s, got {entry!r}")
        found.append((values[0], values[-1]))
    return found
