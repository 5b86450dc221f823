"""The record types every layer shares, and the names of every swappable part.

`stack`, `perception`, `planner` and `controllers` import this module and nothing of each other
below `stack`. It holds plain data: the world snapshot (`WorldState`), the decision (`Command`),
the grid an agent is shown (`GridConfig`), and what flows through one control tick (`EgoState`,
`Reference`, `Actuation`). Behaviour stays in the layers; only small derived views live here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal, Protocol, get_args

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

# --- names of the swappable parts (config keys and CLI options accept exactly these) ---------
AgentName = Literal["ddqn", "dqn", "tabular", "rule", "mobil", "keep-lane", "random"]
LearnedAgentName = Literal["ddqn", "dqn", "tabular"]
Encoding = Literal["observation", "paper", "tabular"]
ControllerName = Literal["pid", "mpc"]
Backend = Literal["fast", "stock"]
AGENT_NAMES: tuple[AgentName, ...] = get_args(AgentName)
LEARNED_AGENTS: tuple[LearnedAgentName, ...] = get_args(LearnedAgentName)
ENCODINGS: tuple[Encoding, ...] = get_args(Encoding)
CONTROLLER_NAMES: tuple[ControllerName, ...] = get_args(ControllerName)
BACKENDS: tuple[Backend, ...] = get_args(Backend)


def unknown_name(kind: str, value: object, options: tuple[str, ...]) -> str:
    """The one-line message for a name that is not among `options`."""
    return f"unknown {kind} {value!r}; available: {', '.join(options)}"


def one_of(kind: str, options: tuple[str, ...]) -> BeforeValidator:
    """A pydantic validator for a name field: anything outside `options` is refused with the
    `unknown_name` message (put before the field's `Literal` check, whose message lists less)."""

    def check(value: object) -> object:
        if value not in options:
            raise ValueError(unknown_name(kind, value, options))
        return value

    return BeforeValidator(check)


# --- seeds ------------------------------------------------------------------------------------
SEED_LIMIT = 2**31 - 1
"""Seeds drawn from a generator lie in [0, SEED_LIMIT)."""


def child_seed(base: int, index: int) -> int:
    """The seed of the `index`-th member (episode, validation episode, evaluation stream) of
    something seeded `base`: `base + index`, so a run's episodes are reproducible one by one and
    do not depend on which process runs them."""
    return base + index


def drawn_seed(rng: np.random.Generator) -> int:
    """A fresh seed drawn from a seeded generator (a gym env's `np_random`)."""
    return int(rng.integers(0, SEED_LIMIT))


# --- the decision ------------------------------------------------------------------------------
class Command(IntEnum):
    """The decision layer's output, in highway-env's LANE_LEFT / IDLE / LANE_RIGHT order."""

    LEFT = 0
    STAY = 1
    RIGHT = 2

    @property
    def lane_shift(self) -> int:
        """Change of lane index: LEFT moves towards lane 0."""
        return self.value - 1


N_ACTIONS = len(Command)
"""Size of every agent's discrete action space."""


# --- the world -----------------------------------------------------------------------------
class Lane(Protocol):
    """The lane-geometry surface the layers use (highway-env's `AbstractLane` satisfies it)."""

    width: float

    def local_coordinates(self, position: np.ndarray) -> tuple[float, float]: ...

    def position(self, longitudinal: float, lateral: float) -> np.ndarray: ...

    def heading_at(self, longitudinal: float) -> float: ...


def lane_curvature(lane: Lane, s: float) -> float:
    """Curvature [1/m] of `lane` at `s`: central difference of its heading over +-1 m."""
    return (lane.heading_at(s + 1.0) - lane.heading_at(s - 1.0)) / 2.0


@dataclass(frozen=True)
class Neighbour:
    """A vehicle ahead of or behind the ego: bumper-to-bumper gap [m] (negative = overlapping) and
    speed [m/s]. The adaptive cruise keeps a time gap to those ahead (its leaders)."""

    gap: float
    speed: float


@dataclass(frozen=True)
class EgoState:
    """The ego in the frame of the reference lane: lateral offset d [m], heading relative to the
    lane [rad], speed [m/s], and the lane's curvature at the ego [1/m] (positive turning left)."""

    d: float
    heading: float
    speed: float
    curvature: float = 0.0


@dataclass(frozen=True)
class WorldState:
    """A snapshot of the road at one control tick, as struct-of-arrays; row 0 is the ego.

    `s` and `d` are the longitudinal and lateral coordinates (m) of each vehicle in the frame of
    the reference lane (lane 0 of the ego's road segment), so lane `k`'s centre lies at
    `d = lane_offsets[k]`. `lanes` gives the geometry of every lane of that segment.
    """

    time: float
    ids: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    velocity: np.ndarray
    lane: np.ndarray
    length: np.ndarray
    width: np.ndarray
    s: np.ndarray
    d: np.ndarray
    crashed: np.ndarray
    lanes: tuple[Lane, ...]
    lane_offsets: np.ndarray

    @property
    def count(self) -> int:
        return len(self.ids)

    @property
    def lanes_count(self) -> int:
        return len(self.lanes)

    @property
    def lane_width(self) -> float:
        return float(self.lanes[0].width)

    @property
    def ego_lane(self) -> int:
        return int(self.lane[0])

    def ego_state(self) -> EgoState:
        """The ego in the reference lane's frame, where `d` is measured, with that lane's curvature."""
        s, reference = float(self.s[0]), self.lanes[0]
        return EgoState(
            d=float(self.d[0]),
            heading=float(self.heading[0]) - reference.heading_at(s),
            speed=float(self.speed[0]),
            curvature=lane_curvature(reference, s),
        )

    def neighbours(self, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
        """(closest vehicle ahead, closest vehicle behind) of the ego among those whose footprint
        reaches into `lane`; ahead/behind by centre position along the road."""
        rel_s = self.s[1:] - self.s[0]
        gap = np.abs(rel_s) - (self.length[1:] + self.length[0]) / 2
        in_lane = np.abs(self.d[1:] - self.lane_offsets[lane]) < (self.lane_width + self.width[1:]) / 2
        found: list[Neighbour | None] = []
        for side in (rel_s > 0, rel_s <= 0):
            candidates = np.flatnonzero(in_lane & side)
            if candidates.size:
                row = candidates[np.argmin(np.abs(rel_s[candidates]))]
                found.append(Neighbour(float(gap[row]), float(self.speed[row + 1])))
            else:
                found.append(None)
        return found[0], found[1]

    def leaders(self, lanes: tuple[int, ...]) -> tuple[Neighbour, ...]:
        """For each lane in `lanes`, the closest vehicle ahead reaching into it (none if nobody)."""
        ahead = (self.neighbours(lane)[0] for lane in lanes)
        return tuple(leader for leader in ahead if leader is not None)


# --- what the agent is shown -----------------------------------------------------------------
MAX_SPEED = 40.0
"""Speed that the grid's `ego_speed` feature maps to 1 [m/s] (highway-env's Vehicle.MAX_SPEED)."""


class GridConfig(BaseModel):
    """The occupancy grid an agent decides on (built by `perception.grid`). Lengths in m, speeds
    in m/s, times in s."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    cell_length: float = Field(5.0, gt=0, allow_inf_nan=False, description="cell length [m]")
    cells_ahead: int = Field(9, ge=1, description="line of sight in cells, the ego's own included")
    cells_behind: int = Field(4, ge=0)
    lanes: Literal["absolute", "ego"] = "absolute"
    lateral_reach: int = Field(1, ge=1, description="ego mode: neighbour lanes on each side")
    footprint: bool = True
    features: tuple[Literal["relative_speed", "ttc", "ego_speed"], ...] = ()
    speed_scale: float = Field(20.0, gt=0, description="relative speed giving feature 1 [m/s]")
    ttc_horizon: float = Field(10.0, gt=0, description="time-to-collision giving feature 1 [s]")

    @property
    def cells(self) -> int:
        return self.cells_behind + self.cells_ahead

    @property
    def ego_column(self) -> int:
        return self.cells_behind

    def rows(self, lanes_count: int) -> int:
        return lanes_count if self.lanes == "absolute" else 2 * self.lateral_reach + 1


def lane_code_bits(lanes: int) -> int:
    """Bits of the binary ego-lane code (the paper's encoding)."""
    return max(1, math.ceil(math.log2(lanes)))


# --- one control tick ------------------------------------------------------------------------
class LateralProfile(Protocol):
    """A lateral reference over time (`controllers.reference.QuinticProfile`)."""

    def sample(self, t: float) -> tuple[float, float, float]:
        """(d [m], d_dot [m/s], d_ddot [m/s^2]) at absolute time `t` [s]."""
        ...


@dataclass(frozen=True)
class Reference:
    """What to track this tick: lateral offset and its first two time derivatives (m, m/s, m/s^2)
    at `time` [s], a set speed [m/s], the leaders to keep a time gap to, and the lane the maneuver
    heads for. `lateral`, when given, is the whole profile, for controllers that look ahead."""

    d: float
    d_dot: float
    d_ddot: float
    set_speed: float
    leaders: tuple[Neighbour, ...] = ()
    time: float = 0.0
    target_lane: int = 0
    lateral: LateralProfile | None = None

    @classmethod
    def sampled(
        cls,
        lateral: LateralProfile,
        time: float,
        set_speed: float,
        leaders: tuple[Neighbour, ...] = (),
        target_lane: int = 0,
    ) -> Reference:
        d, d_dot, d_ddot = lateral.sample(time)
        return cls(d, d_dot, d_ddot, set_speed, leaders, time, target_lane, lateral)

    def preview(self, steps: int, dt: float) -> list[tuple[float, float]]:
        """(d, d_dot) at the next `steps` ticks of `dt` seconds; holds (d, 0) without a profile."""
        if self.lateral is None:
            return [(self.d, 0.0)] * steps
        return [self.lateral.sample(self.time + k * dt)[:2] for k in range(1, steps + 1)]


@dataclass(frozen=True)
class Actuation:
    """What the plant receives each tick: acceleration [m/s^2] and front-wheel steering angle [rad]."""

    acceleration: float
    steering: float
