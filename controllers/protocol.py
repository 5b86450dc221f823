"""The one face every controller shows the loop (built-in, MPC or plug-in): its own module, so the
controllers and the factory that builds them (`controllers.tracker.make_controller`) import it
without importing each other."""

from __future__ import annotations

from typing import Protocol

from records import Actuation, EgoState, Reference


class Controller(Protocol):
    """Steering and throttle for one control tick of a fixed period. `solve_times` [s] holds the
    computing time of every step; `fallbacks` counts steps that fell back to a simpler law."""

    fallbacks: int
    solve_times: list[float]

    def reset(self) -> None: ...

    def step(self, state: EgoState, reference: Reference) -> Actuation: ...
