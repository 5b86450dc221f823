"""MOBIL (Kesting, Treiber & Helbing, 2007) computed from perception, as a classical baseline.

The agent sees what the learned agents see: an ego-relative grid with relative speeds and the ego's
speed. Per adjacent lane it estimates, with IDM, the ego's acceleration behind the new leader and
the new follower's acceleration behind the ego; it changes lane when the follower need not brake
harder than `SAFE_DECELERATION` and the ego gains more than `THRESHOLD` (politeness 0, as
highway-env's IDMVehicle). IDM constants are highway-env's.
"""

from __future__ import annotations

import numpy as np

from planner.agents import Action, Policy
from records import MAX_SPEED, N_ACTIONS, Command, Encoding, GridConfig

ACCELERATION = 3.0
"""IDM maximum acceleration [m/s^2]."""
COMFORT_DECELERATION = 5.0
"""IDM desired deceleration [m/s^2]."""
STANDSTILL_GAP = 5.0
"""IDM jam distance s0 [m] (bumper to bumper)."""
TIME_GAP = 1.5
"""IDM desired time gap T [s]."""
DESIRED_SPEED = 30.0
"""IDM desired speed v0 [m/s] (the highway's speed limit)."""
SAFE_DECELERATION = 2.0
"""MOBIL safety: the new follower must not need to brake harder [m/s^2]."""
THRESHOLD = 0.2
"""MOBIL incentive threshold [m/s^2]."""
FREE_GAP = 1e3
"""Gap used when nobody is in sight [m]."""


def idm(speed: float, leader_speed: float, gap: float) -> float:
    """IDM acceleration [m/s^2] behind a leader `gap` metres ahead (bumper to bumper)."""
    desired = STANDSTILL_GAP + max(
        0.0,
        speed * TIME_GAP
        + speed * (speed - leader_speed) / (2 * np.sqrt(ACCELERATION * COMFORT_DECELERATION)),
    )
    return ACCELERATION * (1 - (max(speed, 0.0) / DESIRED_SPEED) ** 4 - (desired / max(gap, 0.1)) ** 2)


class MobilAgent(Policy):
    """MOBIL on an ego-relative grid (one lane each side) with relative speeds and the ego speed."""

    encoding: Encoding = "observation"
    grid_config: GridConfig

    def __init__(self, grid: GridConfig) -> None:
        self.grid_config = grid.model_copy(
            update={"lanes": "ego", "lateral_reach": 1, "features": ("relative_speed", "ego_speed")}
        )
        self.last_gains: tuple[np.ndarray | None, np.ndarray] = (None, np.zeros(N_ACTIONS))
        """The last observation decided on and its `gains` (`scores` reads them)."""

    def _decode(self, observation: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        g = self.grid_config
        size = 3 * g.cells
        observation = np.asarray(observation, dtype=np.float64).reshape(-1)
        bits = observation.size - 2 * size - 1
        if bits < 1:
            raise ValueError(
                f"mobil agent expected 2 x 3 x {g.cells} grid values, the ego speed and a lane code; "
                f"got {observation.size} values"
            )
        presence = observation[:size].reshape(3, g.cells)
        relative = observation[size : 2 * size].reshape(3, g.cells) * g.speed_scale
        return presence, relative, float(observation[2 * size]) * MAX_SPEED

    def _neighbour(
        self, presence: np.ndarray, relative: np.ndarray, row: int, ahead: bool
    ) -> tuple[float, float] | None:
        """(bumper gap [m], relative speed [m/s]) of the nearest vehicle ahead/behind in `row`."""
        g = self.grid_config
        columns = range(g.ego_column + 1, g.cells) if ahead else range(g.ego_column - 1, -1, -1)
        for column in columns:
            if presence[row, column] > 0:
                distance = abs(column - g.ego_column) * g.cell_length
                return distance - g.cell_length, relative[row, column]
        return None

    score_name = "MOBIL incentive [m/s²]"

    def scores(self, observation: np.ndarray) -> np.ndarray:
        """`gains`, those of the last decision when it was on this very observation."""
        seen, gains = self.last_gains
        return (gains if seen is observation else self.gains(observation)).copy()

    def gains(self, observation: np.ndarray) -> np.ndarray:
        """Per `Command`: the ego's IDM acceleration gain [m/s²] from the change (0 for STAY; NaN
        where the lane is occupied beside the ego or its new follower would brake too hard)."""
        presence, relative, speed = self._decode(observation)
        ego_column = self.grid_config.ego_column
        current = self._neighbour(presence, relative, 1, ahead=True)
        gain_now = idm(speed, speed + current[1], current[0]) if current else idm(speed, speed, FREE_GAP)
        gains = np.full(N_ACTIONS, np.nan)
        gains[Command.STAY] = 0.0
        for command, row in ((Command.LEFT, 0), (Command.RIGHT, 2)):
            if presence[row, ego_column] > 0:
                continue
            leader = self._neighbour(presence, relative, row, ahead=True)
            follower = self._neighbour(presence, relative, row, ahead=False)
            if follower is not None:
                follower_speed = speed + follower[1]
                if idm(follower_speed, speed, follower[0]) < -SAFE_DECELERATION:
                    continue
            gains[command] = (
                idm(speed, speed + leader[1], leader[0]) if leader else idm(speed, speed, FREE_GAP)
            ) - gain_now
        return gains

    def choose(self, observation: np.ndarray) -> Action:
        gains = self.gains(observation)
        self.last_gains = (observation, gains)
        best, best_gain = Command.STAY, THRESHOLD
        for command in (Command.LEFT, Command.RIGHT):
            if gains[command] > best_gain:
                best, best_gain = command, float(gains[command])
        return np.array(best)


MAX_PRIOR = 10.0
"""Largest MOBIL prior a model may declare [reward units]."""


def prior_problem(grid: GridConfig, encoding: Encoding, bonus: float) -> str | None:
    """Why a Q-network seeing `grid` with `encoding` cannot decide with a MOBIL prior of `bonus`,
    or None: MOBIL reads the lanes beside the ego and the relative and ego speeds from the network's
    own observation."""
    if not 0 <= bonus <= MAX_PRIOR:
        return f"expected a bonus in 0..{MAX_PRIOR:g} reward units, got {bonus}"
    needed = ("relative_speed", "ego_speed")
    if bonus and (encoding != "observation" or grid.lanes != "ego" or not set(needed) <= set(grid.features)):
        return "MOBIL needs the observation encoding of ego-relative rows with relative_speed and ego_speed"
    return None


class MobilPrior:
    """The bonus [reward units] a Q-network's greedy decision gives the lane change MOBIL proposes
    on the same observation: MOBIL's change is made when the network rates it at most `bonus`
    below its own best action, so the network keeps the last word on every other decision and on
    changes it rates far worse (on highway-env's traffic, stage 3 rated MOBIL's changes 0.33 below
    staying, median). MOBIL sees the three middle rows of the network's grid, as its own agent
    would."""

    def __init__(self, grid: GridConfig, bonus: float) -> None:
        self.mobil, self.bonus = MobilAgent(grid), bonus
        parts = grid.observation_parts(1)
        reach = grid.lateral_reach
        self.rows = grid.rows(1)
        self.middle = slice(reach - 1, reach + 2)
        self.presence, self.relative = parts["presence"], parts["relative_speed"]
        self.ego_speed, self.lane_start = parts["ego_speed"], parts["lane"].start

    def bonuses(self, observations: np.ndarray) -> np.ndarray:
        """(batch, actions): `bonus` on each row's proposed change, 0 elsewhere."""
        observations = np.asarray(observations, dtype=np.float32).reshape(len(observations), -1)
        added = np.zeros((len(observations), N_ACTIONS), dtype=np.float32)
        for row, observation in enumerate(observations):
            proposal = int(self.mobil.choose(self.mobil_observation(observation)))
            if proposal != Command.STAY:
                added[row, proposal] = self.bonus
        return added

    def mobil_observation(self, observation: np.ndarray) -> np.ndarray:
        """MOBIL's own observation cut out of the network's."""
        presence = observation[self.presence].reshape(self.rows, -1)[self.middle]
        relative = observation[self.relative].reshape(self.rows, -1)[self.middle]
        lane = observation[self.lane_start :]
        return np.concatenate([presence.ravel(), relative.ravel(), observation[self.ego_speed], lane])
