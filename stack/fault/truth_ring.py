"""The truth of the last `REPLAY_S` seconds of a batch of worlds, so a collision's fault is judged
in the batch as one world judges it (`stack.fault.preventability.judge` over `WorldHistory`),
without running the episode again: one entry a tick, the batch's truth (`records.WorldBatch`, made
anew each tick and never changed) and what a `WorldState` has beyond it (positions, crashed flags,
the ego's row in road order, its steering, each world's clock). Bounded memory: 76 ticks, measured
18.5 MB for 64 `highway-v0` worlds (51 vehicles a world), 43 MB for 64 `random` ones (120)."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from records import Lane, WorldState
from records.batch import WorldBatch
from stack.fault.preventability import REPLAY_S, Fault, judge
from stack.sim.batch.arrays import BatchArrays
from stack.sim.batch.world_reading import world_state_of_rows


@dataclass(frozen=True)
class _Tick:
    """One tick of the batch as the ring keeps it: which worlds it stepped (or reset)."""

    stepped: np.ndarray
    batch: WorldBatch
    x: np.ndarray
    y: np.ndarray
    crashed: np.ndarray
    ego: np.ndarray
    steering: np.ndarray
    time: np.ndarray


class TruthRing:
    """The last `REPLAY_S` seconds (plus the frame now) of the batch's truth: `reset` at worlds'
    reset, `record` after every tick, `history(world, lanes)` as the per-world `WorldHistory` holds
    it, or None where this ring cannot say (the world was not stepped on a tick it kept since its
    reset: the caller judges such a world otherwise)."""

    def __init__(self, worlds: int, dt: float) -> None:
        self.dt = dt
        self.ticks: deque[_Tick] = deque(maxlen=round(REPLAY_S / dt) + 1)
        self.started = np.zeros(worlds, dtype=np.int64)
        self.recorded = 0
        """Ticks recorded since the ring was made; `started[w]`: how many when world w was reset."""

    def reset(self, worlds: Sequence[int], batch: WorldBatch, arrays: BatchArrays, time: np.ndarray) -> None:
        """The worlds `worlds` begin an episode at `batch`: their history restarts with it."""
        flags = np.zeros(len(self.started), dtype=bool)
        flags[list(worlds)] = True
        self.started[flags] = self.recorded
        self.record(flags, batch, arrays, time)

    def record(self, stepped: np.ndarray, batch: WorldBatch, arrays: BatchArrays, time: np.ndarray) -> None:
        """One tick of the worlds flagged `stepped`, at `batch` (the truth) and `time` [s]."""
        worlds = np.arange(len(stepped))
        self.ticks.append(
            _Tick(
                stepped.copy(),
                batch,
                arrays.x.copy(),
                arrays.y.copy(),
                arrays.crashed.copy(),
                arrays.ego.copy(),
                arrays.steering[worlds, arrays.ego],
                time.copy(),
            )
        )
        self.recorded += 1

    def judged(self, world: int, kind: str, other: int | None, lanes: tuple[Lane, ...]) -> Fault | None:
        """World `world`'s collision of `kind` with the vehicle of id `other` at its last tick,
        judged as the per-world loop judges it (`judge` over its `history`); None without one."""
        history = self.history(world, lanes)
        return None if history is None else judge(kind, other, history, self.dt)

    def history(self, world: int, lanes: tuple[Lane, ...]) -> list[WorldState] | None:
        """World `world`'s ticks kept since its reset, oldest first, as the per-world loop's
        snapshots (`world_state_of_rows`) on the road of `lanes` (its segment's lanes)."""
        first = self.recorded - len(self.ticks)
        kept = [tick for index, tick in enumerate(self.ticks) if first + index >= self.started[world]]
        if not all(tick.stepped[world] for tick in kept):
            return None
        return [_world_state(tick, world, lanes) for tick in kept]


def _world_state(tick: _Tick, world: int, lanes: tuple[Lane, ...]) -> WorldState:
    """World `world` at `tick` as the per-world loop's snapshot (`world_state_of_rows`)."""
    ego, steering, time = int(tick.ego[world]), float(tick.steering[world]), float(tick.time[world])
    return world_state_of_rows(tick.batch, world, tick.x, tick.y, tick.crashed, ego, steering, time, lanes)
