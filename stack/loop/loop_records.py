"""What the closed loop (`stack.loop.closed_loop`) hands out: the record of one control tick, of one
`act`, its status at a decision point and its controller's solve statistics. Frozen records, so
whoever consumes them (the metrics recorder, the safety monitor, the video, the training MDP) reads
them without changing the loop."""

from __future__ import annotations

from dataclasses import dataclass

from records import Actuation, Reference, WorldState


@dataclass(frozen=True, slots=True)
class Tick:
    """One control tick: the `reference` the maneuver gave, the `actuation` sent to the plant (after
    emergency braking), the `world` it led to (the simulator's truth) and the maneuver's `lane`
    and `target` lane during the tick (equal unless a lane change runs)."""

    reference: Reference
    actuation: Actuation
    world: WorldState
    lane: int
    target: int

    @property
    def changing_lane(self) -> bool:
        return self.target != self.lane


@dataclass(frozen=True)
class Acted:
    """What one `act` did: control ticks run, whether the command was considered (False while a
    lane change was still running), and the ego's mean speed over those ticks [m/s]."""

    ticks: int
    considered: bool
    mean_speed: float


@dataclass(frozen=True)
class LoopStatus:
    """The loop at a decision point: whether the ego crashed, its speed [m/s], the cars it passed,
    the lane changes it started, the commands the safety layer masked and the changes it aborted."""

    crashed: bool
    speed: float
    passed_cars: int
    lane_changes: int
    masked: int
    aborted: int

    def info(self) -> dict[str, float | int | bool]:
        """As a gymnasium `info` dict (the training MDP's; validation reads `crashed` and `speed`)."""
        return {
            "crashed": self.crashed,
            "speed": self.speed,
            "passed_cars": self.passed_cars,
            "lane_changes": self.lane_changes,
            "masked": self.masked,
            "aborted": self.aborted,
        }


@dataclass(frozen=True)
class SolveStatistics:
    """The controller's computing time per control tick of an episode, median and 95th percentile
    [ms] (0 before the first tick), and the ticks on which it fell back to a simpler law."""

    p50_ms: float
    p95_ms: float
    fallbacks: int
