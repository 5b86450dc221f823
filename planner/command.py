"""The decision layer's output: one of three lane commands (highway-env's LANE_LEFT/IDLE/LANE_RIGHT order)."""

from __future__ import annotations

from enum import IntEnum


class Command(IntEnum):
    LEFT = 0
    STAY = 1
    RIGHT = 2

    @property
    def lane_shift(self) -> int:
        """Change of lane index: LEFT moves towards lane 0."""
        return {Command.LEFT: -1, Command.STAY: 0, Command.RIGHT: 1}[self]
