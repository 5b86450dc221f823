"""The drivers' habits beyond IDM and MOBIL (`stack.sim.drivers.DriverHabits`), written once for the
`vector` road and the batch: a distracted driver's IDM acting on a delayed view of its leader and its
sudden brakings without cause, a blind driver's MOBIL not seeing the ego as its new follower, and a
yielding driver easing off for the ego's lane change into its lane. Each per-frame law is a
compiled kernel (or numpy on per-driver arrays) that both roads call on the same inputs; a road
without habits calls none of them, so highway-env's drivers keep stock's bits."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numba import njit

from common.compiled import Kernel
from stack.sim.drivers import SEEN_FRAMES, habits_of
from stack.sim.vector.dynamics import desired_gap

_UNIT = 1.0 / 9007199254740992.0
"""2^-53: a 53-bit integer to a float in [0, 1)."""


@njit(cache=True, nogil=True, inline="always")
def unit_hash(key: int, frame: int) -> float:  # pragma: no cover - compiled
    """A uniform number in [0, 1) for driver `key` at `frame` (splitmix64 of the pair): what a
    random draw gives, without a generator's state, so every road and order gives the same."""
    z = np.uint64(key) + np.uint64(frame + 1) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * _UNIT


@njit(cache=True, nogil=True, inline="always")
def sudden_braking(
    key: int, frame: int, chance: float, frames: int, mps2: float
) -> float:  # pragma: no cover
    """The deceleration [m/s^2] a driver brakes with at `frame` without cause (0: none): `mps2`
    if one of its last `frames` frames (this one included) started a braking, each frame with
    probability `chance` (`unit_hash` of its `key` and the frame)."""
    for onset in range(frame, max(frame - frames, -1), -1):
        if unit_hash(key, onset) < chance:
            return mps2
    return 0.0


@njit(cache=True, nogil=True, inline="always")
def seen_acceleration(
    free: float,
    speed: float,
    a_max: float,
    distance_wanted: float,
    time_wanted: float,
    braking_term: float,
    gap: float,
    closing: float,
) -> float:  # pragma: no cover - compiled
    """IDM's acceleration [m/s^2] of a driver at `speed` [m/s] from the `gap` [m] and `closing`
    speed [m/s] it saw: its free-road acceleration `free` (IDM without a leader, a_max (1 - (v /
    v0)^delta)) - a_max (s*(v, dv) / s)^2, with `desired_gap` and highway-env's 0.01 floor."""
    gap = gap if abs(gap) > 1e-2 else (1e-2 if gap >= 0 else -1e-2)
    ratio = desired_gap(distance_wanted, time_wanted, braking_term, speed, closing) / gap
    return free - a_max * ratio * ratio


@Kernel
def delayed_accelerations(
    acceleration: np.ndarray,
    law_row: np.ndarray,
    me: np.ndarray,
    leader: np.ndarray,
    width: int,
    delay: np.ndarray,
    seen_s: np.ndarray,
    seen_speed: np.ndarray,
    pushed: np.ndarray,
    free: np.ndarray,
    speed: np.ndarray,
    a_max: np.ndarray,
    distance_wanted: np.ndarray,
    time_wanted: np.ndarray,
    braking_term: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Replace, in place, the own-lane IDM `acceleration` [m/s^2] of each driver k with a `delay`
    (frames) and a `leader` by `seen_acceleration` on the gap and closing speed of `delay` frames
    ago (the oldest kept, early on): from `seen_s` and `seen_speed` (worlds, `SEEN_FRAMES`, rows), a
    ring of which `pushed` (per world) frames were written. `me[k]` and `leader[k]` (-1: none) are
    rows world x `width` + row; `free[k]` is the driver's free-road acceleration [m/s^2] (IDM behind
    no leader); its delay, speed [m/s], IDM's a_max [m/s^2], d0 [m], T [s] and 2 sqrt(a b) [m/s^2]
    are at `law_row[k]` of their arrays."""
    frames = seen_s.shape[1]
    for k in range(acceleration.shape[0]):
        row = law_row[k]
        if delay[row] <= 0 or leader[k] < 0:
            continue
        w, mine, theirs = me[k] // width, me[k] % width, leader[k] % width
        then = max(max(pushed[w] - 1 - delay[row], 0), pushed[w] - frames) % frames
        gap = seen_s[w, then, theirs] - seen_s[w, then, mine]
        closing = seen_speed[w, then, mine] - seen_speed[w, then, theirs]
        acceleration[k] = seen_acceleration(
            free[k],
            speed[row],
            a_max[row],
            distance_wanted[row],
            time_wanted[row],
            braking_term[row],
            gap,
            closing,
        )


@Kernel
def sudden_accelerations(
    acceleration: np.ndarray,
    law_row: np.ndarray,
    frame: np.ndarray,
    key: np.ndarray,
    chance: np.ndarray,
    frames: np.ndarray,
    mps2: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Each driver k's `acceleration` [m/s^2], in place, no more than minus its `sudden_braking`
    at its world's `frame[k]` (acts since the reset); its key, chance, frames and deceleration are
    at `law_row[k]` of their arrays."""
    for k in range(acceleration.shape[0]):
        row = law_row[k]
        if chance[row] <= 0:
            continue
        braking = sudden_braking(key[row], frame[k], chance[row], frames[row], mps2[row])
        if braking > 0 and -braking < acceleration[k]:
            acceleration[k] = -braking


def unseen_ego(rears: np.ndarray, blind: np.ndarray, egos: np.ndarray | int) -> np.ndarray:
    """The new followers MOBIL's safety criterion weighs (rows, -1: none): `rears`, but none where
    the deciding driver is `blind` to the ego and the follower is its ego (`egos`, rows)."""
    return np.where(blind & (rears == egos), -1, rears)


def yielding(acceleration: np.ndarray, behind_ego: np.ndarray, comfort_acc_min: np.ndarray) -> np.ndarray:
    """A yielding driver's acceleration [m/s^2]: no more than IDM's behind the ego that changes into
    its lane (`behind_ego`), that no lower than its comfortable deceleration (`comfort_acc_min`,
    negative): it opens the gap without braking hard."""
    return np.minimum(acceleration, np.maximum(behind_ego, comfort_acc_min))


def yielders(
    yields: np.ndarray, lane: np.ndarray, intent: np.ndarray | int, s: np.ndarray, s_ego: np.ndarray | float
) -> np.ndarray:
    """Which drivers yield now: those that `yields`, in the lane the ego shows it is changing into
    (`intent`, -1: none), behind the ego (`s` < `s_ego` [m])."""
    return yields & (intent >= 0) & (lane == intent) & (s < s_ego)


@dataclass(frozen=True, eq=False)
class HabitColumns:
    """The drivers' `DriverHabits` as arrays, one row a driver: delay [frames], sudden-braking
    chance per frame, duration [frames], deceleration [m/s^2] and key, blind to the ego, yielding."""

    delay_frames: np.ndarray
    sudden_braking_chance: np.ndarray
    sudden_braking_frames: np.ndarray
    sudden_braking_mps2: np.ndarray
    key: np.ndarray
    blind_to_ego: np.ndarray
    yields_to_ego: np.ndarray

    @staticmethod
    def of(drivers: list[Any]) -> HabitColumns:
        """The habits of highway-env vehicles (`habits_of`)."""
        habits = [habits_of(v) for v in drivers]
        return HabitColumns(
            np.array([h.delay_frames for h in habits], dtype=np.int64),
            np.array([h.sudden_braking_chance for h in habits], dtype=float),
            np.array([h.sudden_braking_frames for h in habits], dtype=np.int64),
            np.array([h.sudden_braking_mps2 for h in habits], dtype=float),
            np.array([h.key for h in habits], dtype=np.int64),
            np.array([h.blind_to_ego for h in habits], dtype=bool),
            np.array([h.yields_to_ego for h in habits], dtype=bool),
        )

    @cached_property
    def delayed(self) -> bool:
        """Whether a driver acts on a delayed view (a road must keep its vehicles' past)."""
        return bool((self.delay_frames > 0).any())

    @cached_property
    def brakes_suddenly(self) -> bool:
        """Whether a driver brakes without cause."""
        return bool((self.sudden_braking_chance > 0).any())

    @cached_property
    def blind(self) -> bool:
        """Whether a driver is blind to the ego."""
        return bool(self.blind_to_ego.any())

    @cached_property
    def yields(self) -> bool:
        """Whether a driver yields to the ego."""
        return bool(self.yields_to_ego.any())

    @cached_property
    def any(self) -> bool:
        """Whether a driver has a habit at all."""
        return self.delayed or self.brakes_suddenly or self.blind or self.yields


@Kernel
def push_frame(
    seen_s: np.ndarray,
    seen_speed: np.ndarray,
    pushed: np.ndarray,
    worlds: np.ndarray,
    s: np.ndarray,
    speed: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Write the frame's `s` [m] and `speed` [m/s] (world, row) of each of `worlds` into its ring
    (`seen_s`, `seen_speed`: world, slot, row) at the slot after the `pushed` frames, in place."""
    frames = seen_s.shape[1]
    for w in worlds:
        slot = pushed[w] % frames
        for row in range(s.shape[1]):
            seen_s[w, slot, row] = s[w, row]
            seen_speed[w, slot, row] = speed[w, row]
        pushed[w] += 1


class SeenPast:
    """The last `SEEN_FRAMES` frames' s [m] and speed [m/s] of every row of `worlds` worlds of
    `rows` rows each, as rings, and how many frames each world pushed since its reset."""

    def __init__(self, worlds: int, rows: int) -> None:
        self.s = np.zeros((worlds, SEEN_FRAMES, rows))
        self.speed = np.zeros((worlds, SEEN_FRAMES, rows))
        self.pushed = np.zeros(worlds, dtype=np.int64)

    @staticmethod
    def grown(kept: SeenPast | None, worlds: int, rows: int) -> SeenPast:
        """`kept` if it holds `rows` rows, else a past of `rows` rows holding what `kept` held."""
        if kept is not None and kept.s.shape[2] >= rows:
            return kept
        grown = SeenPast(worlds, rows)
        if kept is not None:
            held = kept.s.shape[2]
            grown.s[:, :, :held], grown.speed[:, :, :held] = kept.s, kept.speed
            grown.pushed[:] = kept.pushed
        return grown

    def push(self, worlds: np.ndarray, s: np.ndarray, speed: np.ndarray) -> None:
        """Write this frame's `s` and `speed` of `worlds` (rows of `s` and `speed`: every world,
        one row each) into their rings (`push_frame`)."""
        push_frame(self.s, self.speed, self.pushed, worlds, s, speed)
