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

The decision is one plain function (`rank_vehicles`, the scene read by
`planner.lookahead_scene.read_vehicles`, the rollout `planner.lookahead_rollout.rollout`) that numba
compiles for one scene (`LookaheadAgent.rank`) and into one loop over a batch of observations
(`LookaheadAgent.choose_batch`, which batched worlds call once for every world deciding): one world
decides as one row of a batch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba.extending import register_jitable

from common.compiled import Kernel
from common.longitudinal import BrakingLimits, GapKeeping
from common.neighbours import VehicleRows
from planner.agents import Action, Policy
from planner.lookahead_config import LookaheadConfig
from planner.lookahead_rollout import EgoModel, rollout
from planner.lookahead_scene import (
    EGO_LENGTH,
    REACH,
    Scene,
    SceneLayout,
    checked_size,
    lookahead_grid,
    read_vehicles,
    scene_layout,
)
from planner.safety import SafetyConfig, SafetySettings, change_is_safe, safety_settings
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

    def ego(self) -> EgoModel:
        """The rollout's ego (`lookahead_rollout.EgoModel`): the cruise's and emergency braking's
        law records as the stack's controllers hold them."""
        return EgoModel(
            GapKeeping(self.time_gap, self.standstill_gap),
            BrakingLimits(self.emergency_decel, self.comfort_decel, self.emergency_ttc),
            self.set_speed,
            self.kp_speed,
            self.max_accel,
            EGO_LENGTH,
            self.width,
            self.lane_width,
        )

    def change_duration(self, speed: float) -> float:
        """A lane change's duration at `speed` [m/s]: nominal, stretched so its peak lateral speed
        stays within speed x tan(max_course) (`controllers.reference.drivable_duration`)."""
        return change_duration(self.lane_change_s, math.tan(self.max_course), self.min_change_speed,
                               self.lane_width, speed)  # fmt: skip


@register_jitable
def change_duration(
    nominal: float, course_slope: float, min_change_speed: float, lane_width: float, speed: float
) -> float:
    """A lane change's duration [s] at `speed` [m/s]: `nominal`, stretched so its peak lateral
    speed stays within speed x `course_slope` (the tangent of the largest course)."""
    reachable = max(speed, min_change_speed, 1e-3) * course_slope
    return max(nominal, QUINTIC_PEAK_SPEED * lane_width / reachable)


@dataclass(frozen=True)
class LookaheadSetup:
    """Everything the lookahead takes from the run config: its own settings, the driving model and
    the safety layer's gaps (so it never proposes a command the layer masks)."""

    config: LookaheadConfig = field(default_factory=LookaheadConfig)
    driving: DrivingModel = field(default_factory=DrivingModel)
    safety: SafetyConfig = field(default_factory=SafetyConfig)


class RankSettings(NamedTuple):
    """A decision's settings as compiled code takes them: the rollout's steps and step [s]; the
    score's `LookaheadConfig` fields (same names and units); the maneuver's nominal lane-change
    duration [s], the tangent of its largest course, the speed below which no change starts [m/s]."""

    steps: int
    step_s: float
    terminal_s: float
    option_discount: float
    weight_progress: float
    weight_ttc: float
    weight_comfort: float
    ttc_floor_s: float
    ttc_good_s: float
    margin: float
    comfort_lateral_mps2: float
    comfort_lateral_jerk_mps3: float
    lane_change_s: float
    course_slope: float
    min_change_speed: float


def rank_settings(setup: LookaheadSetup) -> RankSettings:
    """`setup`'s `RankSettings`."""
    config, driving = setup.config, setup.driving
    return RankSettings(
        max(1, round(config.horizon_s / config.step_s)),
        config.step_s,
        config.terminal_s,
        config.option_discount,
        config.weight_progress,
        config.weight_ttc,
        config.weight_comfort,
        config.ttc_floor_s,
        config.ttc_good_s,
        config.margin,
        config.comfort_lateral_mps2,
        config.comfort_lateral_jerk_mps3,
        driving.lane_change_s,
        math.tan(driving.max_course),
        driving.min_change_speed,
    )


@dataclass(frozen=True)
class Ranking:
    """One decision's candidates (`COMMANDS` order, those rolled out), their scores in [0, 1] and
    the command chosen."""

    commands: tuple[Command, ...]
    scores: np.ndarray
    chosen: Command


class LookaheadAgent(Policy):
    """Rolls out LEFT / STAY / RIGHT with the stack's own models and picks the best-scoring one
    (see the module docstring); decides for a batch of worlds at once with `choose_batch`."""

    encoding: Encoding = "observation"
    grid_config: GridConfig

    def __init__(self, grid: GridConfig, setup: LookaheadSetup | None = None) -> None:
        self.grid_config = lookahead_grid(grid)
        self.setup = setup or LookaheadSetup()
        self._ego = self.setup.driving.ego()
        self._safety = safety_settings(self.setup.safety)
        self._settings = rank_settings(self.setup)
        self._layout = scene_layout(self.grid_config)

    def choose(self, observation: np.ndarray) -> Action:
        observations = np.asarray(observation, dtype=np.float64).reshape(1, -1)
        return np.array(Command(int(self.choose_batch(observations)[0])))

    def choose_batch(self, observations: np.ndarray) -> np.ndarray:
        """(worlds,) int64 `Command` values: the command `choose` gives on each row of
        `observations` (worlds, size), decided in one compiled call."""
        observations = np.ascontiguousarray(observations, dtype=np.float64)
        if observations.ndim != 2:
            raise ValueError(
                f"lookahead agent expected (worlds, values) observations, got {observations.shape}"
            )
        checked_size(self.grid_config, observations.shape[1])
        commands = np.empty(observations.shape[0], dtype=np.int64)
        _choose_worlds(observations, self._layout, self._ego, self._settings, self._safety, commands)
        return commands

    def permitted(self, scene: Scene) -> tuple[Command, ...]:
        """The commands to roll out: STAY, and each change to a lane that exists, that the safety
        layer would pass (on the vehicles as read) and that the maneuver would start at this speed."""
        return self.rank(scene).commands

    def rank(self, scene: Scene) -> Ranking:
        """Roll out the permitted commands, score them, pick with hysteresis (`rank_vehicles`)."""
        shifts, scores = np.empty(len(COMMANDS), dtype=np.int64), np.empty(len(COMMANDS))
        rolled, best = _rank_one(
            scene.speed, scene.left, scene.right, scene.lane, scene.centre, scene.length,
            scene.velocity, self._ego, self._settings, self._safety, shifts, scores,
        )  # fmt: skip
        commands = tuple(Command(int(shift) + 1) for shift in shifts[:rolled])
        return Ranking(commands, scores[:rolled].copy(), commands[best])


@register_jitable
def gap_clear(
    speed: float,
    lane: np.ndarray,
    centre: np.ndarray,
    length: np.ndarray,
    velocity: np.ndarray,
    shift: int,
    safety: SafetySettings,
) -> bool:
    """The safety layer's rule for a change to lane `shift` (`planner.safety.change_is_safe`) on
    the vehicles as read: the gap rule there, and no vehicle alongside in the lane beyond it. The
    scene as the rule takes one world: row 0 the ego at s 0, each vehicle's d its lane relative to
    the ego's (the scene's `REACH` lanes on each side centred at -REACH .. REACH), reaching half a
    lane, where it is now."""
    if not safety.enabled:
        return True
    count = lane.shape[0] + 1
    s, d, speeds, lengths = np.zeros(count), np.zeros(count), np.empty(count), np.empty(count)
    s[1:], d[1:], speeds[1:], lengths[1:] = centre, lane, velocity, length
    speeds[0], lengths[0] = speed, EGO_LENGTH
    rows = VehicleRows(count, s, d, speeds, lengths, np.full(count, 0.5), np.zeros(count))
    offsets = np.arange(-REACH, REACH + 1).astype(np.float64)
    return change_is_safe(rows, offsets, offsets.shape[0], REACH, REACH + shift, safety)


@register_jitable
def rank_vehicles(
    speed: float,
    left: int,
    right: int,
    lane: np.ndarray,
    centre: np.ndarray,
    length: np.ndarray,
    velocity: np.ndarray,
    ego: EgoModel,
    settings: RankSettings,
    safety: SafetySettings,
    shifts: np.ndarray,
    scores: np.ndarray,
) -> tuple[int, int]:
    """One decision on the scene (the ego at `speed` [m/s], `left` / `right` lanes beside it, the
    vehicles read): (candidates rolled out, the chosen one's index), their lane shifts and scores
    in [0, 1] written to the first rows of `shifts` and `scores` (`COMMANDS` order).

    Candidates: STAY, and each change to a lane that exists, that the safety layer would pass
    (`gap_clear`) and that the maneuver would start at this speed. Each rollout's score is the
    gated weighted mean of progress, TTC and comfort; when every rollout is gated, the one without
    an at-fault collision and with the largest TTC ranks first (scores below 2e-3) and no
    hysteresis holds the lane; otherwise a change must beat STAY by `margin`."""
    rolled = 1
    shifts[0] = 0
    for shift, exists in ((-1, left > 0), (1, right > 0)):
        if (
            exists
            and speed >= settings.min_change_speed
            and gap_clear(speed, lane, centre, length, velocity, shift, safety)
        ):
            shifts[rolled] = shift
            rolled += 1
    duration = change_duration(
        settings.lane_change_s, settings.course_slope, settings.min_change_speed, ego.lane_width, speed
    )
    durations = np.zeros(rolled)
    for k in range(rolled):
        if shifts[k] != 0:
            durations[k] = duration
    outcome = rollout(
        shifts[:rolled], durations, speed, lane, centre, length, velocity, ego,
        settings.steps, settings.step_s, left, right,
    )  # fmt: skip
    lateral_bound = QUINTIC_PEAK_ACCELERATION * ego.lane_width / math.pow(duration, 2.0)
    jerk_bound = QUINTIC_PEAK_JERK * ego.lane_width / math.pow(duration, 3.0)
    progress = np.empty(rolled)
    for k in range(rolled):
        option = settings.option_discount * outcome[k, 5]
        progress[k] = outcome[k, 2] + settings.terminal_s * max(outcome[k, 4], option)
    best_progress = max(progress.max(), 1e-6)
    weights = settings.weight_progress + settings.weight_ttc + settings.weight_comfort
    all_gated = True
    for k in range(rolled):
        at_fault, min_ttc, emergency = outcome[k, 0], outcome[k, 1], outcome[k, 3]
        changes = shifts[k] != 0
        lateral = lateral_bound if changes else 0.0
        jerk = jerk_bound if changes else 0.0
        kept = (1.0 if lateral <= settings.comfort_lateral_mps2 else 0.0) + (
            1.0 if jerk <= settings.comfort_lateral_jerk_mps3 else 0.0
        )
        comfort = (kept + (1.0 if emergency == 0 else 0.0)) / 3
        ttc = (min_ttc - settings.ttc_floor_s) / (settings.ttc_good_s - settings.ttc_floor_s)
        ttc = min(max(ttc, 0.0), 1.0)
        share = progress[k] / best_progress
        score = (
            settings.weight_progress * share + settings.weight_ttc * ttc + settings.weight_comfort * comfort
        ) / weights
        gated = at_fault > 0 or min_ttc < settings.ttc_floor_s
        all_gated = all_gated and gated
        scores[k] = 0.0 if gated else score
    if all_gated:
        for k in range(rolled):
            at_fault, min_ttc = outcome[k, 0], outcome[k, 1]
            scores[k] = 1e-3 * (1.0 if at_fault == 0 else 0.0) + 1e-4 * min(min_ttc, 10.0) / 10.0
    best = 0
    for k in range(1, rolled):
        if scores[k] > scores[best]:
            best = k
    if not all_gated and scores[best] < scores[0] + settings.margin:
        best = 0
    return rolled, best


_rank_one = Kernel(rank_vehicles)


@Kernel
def _choose_worlds(
    observations: np.ndarray,
    layout: SceneLayout,
    ego: EgoModel,
    settings: RankSettings,
    safety: SafetySettings,
    commands: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through LookaheadAgent.choose_batch
    """`rank_vehicles` on the scene of each row of `observations`: its chosen `Command` value in
    `commands`."""
    room = (2 * REACH + 1) * layout.cells
    lane, centre = np.empty(room, dtype=np.int64), np.empty(room)
    length, velocity = np.empty(room), np.empty(room)
    shifts, scores = np.empty(3, dtype=np.int64), np.empty(3)
    for w in range(observations.shape[0]):
        count, speed, left, right = read_vehicles(layout, observations[w], lane, centre, length, velocity)
        _, best = rank_vehicles(
            speed, left, right, lane[:count], centre[:count], length[:count], velocity[:count],
            ego, settings, safety, shifts, scores,
        )  # fmt: skip
        commands[w] = shifts[best] + 1
