"""The record `drivestack track` keeps of one tracked lane change (a row of tracking.json), in its
own module so the command (`stack.apps.track`) and its report (`stack.apps.track_report`) both
read it without importing each other."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from stack.loop.metrics import Tracking


@dataclass(frozen=True)
class TrackedLaneChange(Tracking):
    """One lane change as `drivestack track` drove it: which, how it tracked (`Tracking`), the
    controller's time per tick [ms] and fallbacks, whether it `started` at all (not below the
    minimum lane-change speed: then the record is lane keeping); it starts at `speed` and the
    cruise's set speed is `end_speed` [m/s] (a maneuver that brakes or accelerates while it changes
    lane when they differ); `trace` holds the time series used by the plots."""

    controller: str
    road: str
    plant: str
    speed: float
    direction: str
    end_speed: float
    solve_ms_p50: float
    solve_ms_p95: float
    fallbacks: int
    started: bool = True
    trace: dict[str, list[float]] = field(default_factory=dict)

    def record(self) -> dict:
        """The flat record of tracking.json: which maneuver first, then its figures."""
        figures = {k: v for k, v in asdict(self).items() if k != "trace"}
        which = ("controller", "road", "plant", "speed", "end_speed", "direction")
        return {**{k: figures.pop(k) for k in which}, **figures}
