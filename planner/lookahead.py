"""The lookahead agent: PDM-Closed (Dauner et al., 2023) for the stack's LEFT / STAY / RIGHT.

At each decision it rolls every command the safety layer would pass through the stack's own
maneuver and adaptive cruise (`planner.lookahead_rollout`), the others forecast from what perception
shows (`planner.lookahead_scene`), for `horizon_s`. A rollout with an at-fault collision or a TTC
below `ttc_floor_s` is gated (score 0); a command to a lane that does not exist is never rolled out.
The others are scored by the weighted mean of progress (the distance driven over the best
command's), TTC (0 at the floor, 1 from `ttc_good_s`) and comfort (the share of its bounds the
rollout keeps: lateral acceleration, lateral jerk, no emergency braking). The agent keeps its current
command, keeping the lane (it decides only while the ego keeps its lane: the loop does not ask it
during a change), unless a change scores at least `margin` more: ties and near-ties stay.
"""

from __future__ import annotations

import math
from dataclasses import astuple, dataclass, field

import numpy as np

from common.neighbours import VehicleRows
from planner.agents import Action, Policy
from planner.lookahead_config import LookaheadConfig
from planner.lookahead_rollout import rollout
from planner.lookahead_scene import EGO_LENGTH, REACH, Scene, lookahead_grid, read_scene
from planner.safety import SafetyConfig, change_is_safe_compiled, safety_settings
from records import Command, Encoding, GridConfig

QUINTIC_PEAK_SPEED = 15.0 / 8.0
"""The quintic's peak lateral speed per (distance / duration) (`controllers.reference`)."""
QUINTIC_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
"""Its peak lateral acceleration per (distance / duration^2)."""
QUINTIC_PEAK_JERK = 60.0
"""Its peak lateral jerk per (distance / duration^3)."""
COMMANDS = (Command.STAY, Command.LEFT, Command.RIGHT)
"""The order commands are rolled out and ranked in: on a tie, the first wins."""


@dataclass(frozen=True)
class DrivingModel:
    """The stack's maneuver and adaptive cruise, as the rollout models them (`controllers.config`
    defaults): cruise set speed [m/s], time gap [s], standstill gap [m], comfort deceleration,
    largest acceleration, speed gain [1/s], emergency deceleration [m/s^2] and trigger TTC [s];
    ego width and lane width [m]; nominal lane-change duration [s], the course that stretches it
    at low speed [rad], the speed below which no change starts [m/s]."""

    set_speed: float = 30.0
    time_gap: float = 1.5
    standstill_gap: float = 8.0
    comfort_decel: float = 3.0
    max_accel: float = 2.0
    kp_speed: float = 0.6
    emergency_decel: float = 5.0
    emergency_ttc: float = 1.0
    width: float = 2.0
    lane_width: float = 4.0
    lane_change_s: float = 5.0
    max_course: float = math.radians(12.0)
    min_change_speed: float = 3.0

    def ego(self) -> np.ndarray:
        """The rollout's ego parameters (`lookahead_rollout.EGO`)."""
        return np.array(astuple(self)[:8] + (EGO_LENGTH, self.width, self.lane_width))

    def change_duration(self, speed: float) -> float:
        """A lane change's duration at `speed` [m/s]: nominal, stretched so its peak lateral speed
        stays within speed x tan(max_course) (`controllers.reference.drivable_duration`)."""
        reachable = max(speed, self.min_change_speed, 1e-3) * math.tan(self.max_course)
        return max(self.lane_change_s, QUINTIC_PEAK_SPEED * self.lane_width / reachable)


@dataclass(frozen=True)
class LookaheadSetup:
    """Everything the lookahead takes from the run config: its own settings, the driving model and
    the safety layer's gaps (so it never proposes a command the layer masks)."""

    config: LookaheadConfig = field(default_factory=LookaheadConfig)
    driving: DrivingModel = field(default_factory=DrivingModel)
    safety: SafetyConfig = field(default_factory=SafetyConfig)


@dataclass(frozen=True)
class Ranking:
    """One decision's candidates (`COMMANDS` order, those rolled out), their scores in [0, 1] and
    the command chosen."""

    commands: tuple[Command, ...]
    scores: np.ndarray
    chosen: Command


class LookaheadAgent(Policy):
    """Rolls out LEFT / STAY / RIGHT with the stack's own models and picks the best-scoring one
    (see the module docstring)."""

    encoding: Encoding = "observation"
    grid_config: GridConfig

    def __init__(self, grid: GridConfig, setup: LookaheadSetup | None = None) -> None:
        self.grid_config = lookahead_grid(grid)
        self.setup = setup or LookaheadSetup()
        self._ego = self.setup.driving.ego()
        self._safety = safety_settings(self.setup.safety)
        config = self.setup.config
        self._steps = max(1, round(config.horizon_s / config.step_s))

    def choose(self, observation: np.ndarray) -> Action:
        return np.array(self.rank(read_scene(self.grid_config, observation)).chosen)

    def permitted(self, scene: Scene) -> tuple[Command, ...]:
        """The commands to roll out: STAY, and each change to a lane that exists, that the safety
        layer would pass (on the vehicles as read) and that the maneuver would start at this speed."""
        found = [Command.STAY]
        driving = self.setup.driving
        for command, exists in ((Command.LEFT, scene.left > 0), (Command.RIGHT, scene.right > 0)):
            if (
                exists
                and scene.speed >= driving.min_change_speed
                and self._gap_clear(scene, command.lane_shift)
            ):
                found.append(command)
        return tuple(found)

    def _gap_clear(self, scene: Scene, shift: int) -> bool:
        """The safety layer's rule for a change to lane `shift` (`planner.safety.change_is_safe`) on
        the vehicles as read: the gap rule there, and no vehicle alongside in the lane beyond it."""
        if not self._safety.enabled:
            return True
        rows, offsets = _rows(scene), np.arange(-REACH, REACH + 1, dtype=np.float64)
        return bool(change_is_safe_compiled(rows, offsets, len(offsets), REACH, REACH + shift, self._safety))

    def rank(self, scene: Scene) -> Ranking:
        """Roll out the permitted commands, score them, pick with hysteresis."""
        commands = self.permitted(scene)
        config, driving = self.setup.config, self.setup.driving
        shifts = np.array([command.lane_shift for command in commands], dtype=np.int64)
        duration = driving.change_duration(scene.speed)
        durations = np.where(shifts != 0, duration, 0.0)
        outcome = rollout(
            shifts,
            durations,
            scene.speed,
            scene.lane,
            scene.centre,
            scene.length,
            scene.velocity,
            self._ego,
            self._steps,
            config.step_s,
            scene.left,
            scene.right,
        )
        scores, fallback = self.scores(outcome, shifts != 0, duration)
        best = int(np.argmax(scores))
        if not fallback and scores[best] < scores[0] + config.margin:
            best = 0
        return Ranking(commands, scores, commands[best])

    def scores(self, outcome: np.ndarray, changes: np.ndarray, duration: float) -> tuple[np.ndarray, bool]:
        """Per rollout, the gated weighted score in [0, 1], and whether every rollout is gated:
        then the one without an at-fault collision and with the largest TTC ranks first (scores
        below 2e-3), and no hysteresis holds the lane."""
        config = self.setup.config
        at_fault, min_ttc, driven, emergency, end_speed, option = outcome.T
        progress = driven + config.terminal_s * np.maximum(end_speed, config.option_discount * option)
        distance = self.setup.driving.lane_width
        lateral = np.where(changes, QUINTIC_PEAK_ACCELERATION * distance / duration**2, 0.0)
        jerk = np.where(changes, QUINTIC_PEAK_JERK * distance / duration**3, 0.0)
        comfort = (
            (lateral <= config.comfort_lateral_mps2).astype(float)
            + (jerk <= config.comfort_lateral_jerk_mps3)
            + (emergency == 0)
        ) / 3
        ttc = np.clip((min_ttc - config.ttc_floor_s) / (config.ttc_good_s - config.ttc_floor_s), 0.0, 1.0)
        share = progress / max(float(progress.max()), 1e-6)
        weights = config.weight_progress + config.weight_ttc + config.weight_comfort
        score = (
            config.weight_progress * share + config.weight_ttc * ttc + config.weight_comfort * comfort
        ) / weights
        gated = (at_fault > 0) | (min_ttc < config.ttc_floor_s)
        if gated.all():
            return 1e-3 * (at_fault == 0) + 1e-4 * np.minimum(min_ttc, 10.0) / 10.0, True
        return np.where(gated, 0.0, score), False


def _rows(scene: Scene) -> VehicleRows:
    """The scene as the safety layer's compiled rule takes one world (`planner.safety.change_is_safe`):
    row 0 the ego at s 0, each vehicle's d its lane relative to the ego's (the scene's `REACH` lanes
    on each side centred at -REACH .. REACH), reaching half a lane, where it is now."""
    count = scene.lane.size + 1
    s = np.concatenate(([0.0], scene.centre))
    d = np.concatenate(([0.0], scene.lane.astype(np.float64)))
    speed = np.concatenate(([scene.speed], scene.velocity))
    length = np.concatenate(([EGO_LENGTH], scene.length))
    return VehicleRows(count, s, d, speed, length, np.full(count, 0.5), np.zeros(count))
