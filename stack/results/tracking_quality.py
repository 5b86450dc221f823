"""Tracking quality against the simulator's truth: what `drivestack tracking` reports of the world
the layers act on (the confirmed tracks, or each frame's raw detections with the tracker off).

Every control tick the perceived vehicles are matched to the true ones by scipy's
`linear_sum_assignment` on their distance in the lane frame (s, d); a pair within `MATCH_M` is
a true positive. Within `QUALITY_RANGE_M` of the ego (along the road): precision (true
positives / perceived vehicles), recall (true positives / true vehicles), position and
velocity RMSE over the true positives (velocity in the lane frame, from each one's speed and
heading), and OSPA (cut-off `OSPA_CUTOFF_M`, order 2) averaged over the ticks with a vehicle
perceived or true; identity switches (CLEAR-MOT's IDSW), the true positives whose perceived
id differs from the one the same true vehicle was last matched to, a minute of driving (a track
lost and started again on a vehicle that swerves counts one: the layers then lose its history).
Over the whole road: phantom tracks, the perceived vehicles (by id; a raw phantom detection is
one a frame) never matched to a true one, a minute of driving."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from perception.sensor import PHANTOM_ID_BASE
from perception.tracking import TRACK_ID_BASE
from records import WorldState

QUALITY_RANGE_M = 60.0
"""Vehicles within this of the ego along the road are scored [m]."""
MATCH_M = 3.0
"""A perceived vehicle within this of a true one is that vehicle [m]."""
OSPA_CUTOFF_M = 10.0
"""OSPA's cut-off c [m] (order p = 2)."""


def lane_frame(world: WorldState) -> tuple[np.ndarray, np.ndarray]:
    """The other vehicles' positions (s, d) and velocities along and across the lane at the ego
    [m, m/s], (vehicles, 2) each."""
    heading = world.heading[1:] - world.lanes[0].heading_at(float(world.s[0]))
    position = np.stack([world.s[1:], world.d[1:]], axis=1)
    speed = world.speed[1:]
    return position, np.stack([speed * np.cos(heading), speed * np.sin(heading)], axis=1)


def matched(truth: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(true rows, perceived rows, distances [m]) of the optimal assignment of `seen` to `truth`
    positions (n, 2)."""
    if not len(truth) or not len(seen):
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros(0)
    distance = np.linalg.norm(truth[:, None, :] - seen[None, :, :], axis=2)
    rows, columns = linear_sum_assignment(distance)
    return rows, columns, distance[rows, columns]


@dataclass
class TrackingQuality:
    """Counts over ticks (`record`) that make the measures (`measures`)."""

    ticks: int = 0
    true_positives: int = 0
    perceived: int = 0
    true: int = 0
    position_sq: float = 0.0
    velocity_sq: float = 0.0
    ospa: list[float] = field(default_factory=list)
    seen: set[tuple[int, int]] = field(default_factory=set)
    real: set[tuple[int, int]] = field(default_factory=set)
    identity_switches: int = 0
    last_match: dict[int, int] = field(default_factory=dict)

    def record(self, truth: WorldState, perceived: WorldState) -> None:
        """One tick: the true world and the world the layers act on."""
        self.ticks += 1
        true_at, true_velocity = lane_frame(truth)
        seen_at, seen_velocity = lane_frame(perceived)
        keys = [self._key(int(ident)) for ident in perceived.ids[1:]]
        self.seen.update(keys)
        rows, columns, distance = matched(true_at, seen_at)
        self.real.update(keys[c] for c, gap in zip(columns, distance, strict=True) if gap <= MATCH_M)
        near_true = np.abs(true_at[:, 0] - truth.s[0]) <= QUALITY_RANGE_M
        near_seen = np.abs(seen_at[:, 0] - perceived.s[0]) <= QUALITY_RANGE_M
        self.true += int(near_true.sum())
        self.perceived += int(near_seen.sum())
        rows, columns, distance = matched(true_at[near_true], seen_at[near_seen])
        hit = distance <= MATCH_M
        self.true_positives += int(hit.sum())
        self.position_sq += float((distance[hit] ** 2).sum())
        error = true_velocity[near_true][rows[hit]] - seen_velocity[near_seen][columns[hit]]
        self.velocity_sq += float((error**2).sum())
        true_ids = truth.ids[1:][near_true][rows[hit]]
        seen_ids = perceived.ids[1:][near_seen][columns[hit]]
        for true_id, seen_id in zip(true_ids.tolist(), seen_ids.tolist(), strict=True):
            self.identity_switches += self.last_match.get(true_id, seen_id) != seen_id
            self.last_match[true_id] = seen_id
        largest = max(int(near_true.sum()), int(near_seen.sum()))
        if largest:
            cut = np.minimum(distance, OSPA_CUTOFF_M) ** 2
            unmatched = largest - len(distance)
            self.ospa.append(math.sqrt((cut.sum() + OSPA_CUTOFF_M**2 * unmatched) / largest))

    def _key(self, ident: int) -> tuple[int, int]:
        """A perceived vehicle's identity over the episode: its id, and for a raw phantom detection
        (a new one each observation) the tick too."""
        return (ident, self.ticks) if PHANTOM_ID_BASE <= ident < TRACK_ID_BASE else (ident, 0)

    def measures(self, dt: float) -> dict[str, float]:
        """The measures (module docstring) of the ticks recorded, `dt` [s] apart."""
        positives = max(self.true_positives, 1)
        minutes = self.ticks * dt / 60.0
        return {
            "precision": self.true_positives / max(self.perceived, 1),
            "recall": self.true_positives / max(self.true, 1),
            "position_rmse_m": math.sqrt(self.position_sq / positives),
            "velocity_rmse_mps": math.sqrt(self.velocity_sq / positives),
            "ospa_m": float(np.mean(self.ospa)) if self.ospa else 0.0,
            "phantom_tracks_per_min": len(self.seen - self.real) / minutes if minutes else 0.0,
            "identity_switches_per_min": self.identity_switches / minutes if minutes else 0.0,
            "minutes": minutes,
        }

    @property
    def phantom_tracks(self) -> int:
        """Perceived vehicles never matched to a true one."""
        return len(self.seen - self.real)


def combined(episodes: list[TrackingQuality], dt: float) -> dict[str, float]:
    """The measures (module docstring) of `episodes` together, ticks `dt` [s] apart."""
    total = TrackingQuality(
        sum(e.ticks for e in episodes),
        sum(e.true_positives for e in episodes),
        sum(e.perceived for e in episodes),
        sum(e.true for e in episodes),
        sum(e.position_sq for e in episodes),
        sum(e.velocity_sq for e in episodes),
        [value for e in episodes for value in e.ospa],
        identity_switches=sum(e.identity_switches for e in episodes),
    )
    measures = total.measures(dt)
    minutes = measures["minutes"]
    measures["phantom_tracks_per_min"] = sum(e.phantom_tracks for e in episodes) / minutes if minutes else 0.0
    return measures
