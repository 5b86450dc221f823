"""Who is around the ego in a lane: the gaps the controllers and the safety layer work with."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from perception.types import WorldState


@dataclass(frozen=True)
class Neighbour:
    """A vehicle ahead of or behind the ego: bumper-to-bumper gap [m] (negative = overlapping) and
    speed [m/s]."""

    gap: float
    speed: float


def _in_lane(world: WorldState, lane: int) -> np.ndarray:
    """Mask of the other vehicles whose footprint reaches into `lane`."""
    reach = (world.lane_width + world.width[1:]) / 2
    return np.abs(world.d[1:] - world.lane_offsets[lane]) < reach


def neighbours(world: WorldState, lane: int) -> tuple[Neighbour | None, Neighbour | None]:
    """(closest vehicle ahead, closest vehicle behind) of the ego among those reaching into `lane`;
    ahead/behind by centre position along the road."""
    rel_s = world.s[1:] - world.s[0]
    gap = np.abs(rel_s) - (world.length[1:] + world.length[0]) / 2
    in_lane = _in_lane(world, lane)
    found = []
    for side in (rel_s > 0, rel_s <= 0):
        candidates = np.flatnonzero(in_lane & side)
        if candidates.size:
            row = candidates[np.argmin(np.abs(rel_s[candidates]))]
            found.append(Neighbour(float(gap[row]), float(world.speed[row + 1])))
        else:
            found.append(None)
    return found[0], found[1]


def leaders(world: WorldState, lanes: tuple[int, ...]) -> list[tuple[float, float]]:
    """For each lane in `lanes`, the closest vehicle ahead reaching into it, as (gap [m], speed
    [m/s]); lanes with nobody ahead are left out."""
    found = []
    for lane in lanes:
        ahead, _ = neighbours(world, lane)
        if ahead is not None:
            found.append((ahead.gap, ahead.speed))
    return found
