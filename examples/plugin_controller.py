"""A controller plug-in in a plain file (docs/plugins.md).

    drivestack track --controller pid,examples/plugin_controller.py:HeadingPD --plant kinematic
    drivestack run --controller examples/plugin_controller.py:HeadingPD --episodes 2
    .venv/bin/python examples/plugin_controller.py     # one episode through the Python API

The `Controller` protocol: `reset()`, `step(state, reference) -> Actuation` once per control tick,
and the counters `fallbacks` (steps that fell back to a simpler law) and `solve_times` (seconds per
step). The constructor may ask for `config` (the run's controller section), `dt` [s] and `plant`.
"""

import math
import time
from pathlib import Path

from controllers.cruise import AdaptiveCruise
from records import Actuation, EgoState, Reference


class HeadingPD:
    """Steering from the lateral error and the heading, each with one gain; throttle from the
    stack's adaptive cruise. Deliberately simple: no feedforward, so it lags a lane change."""

    LATERAL_GAIN = 0.01
    """Steering per metre of lateral error [rad/m]."""
    HEADING_GAIN = 0.8
    """Steering per radian of heading error towards the reference course [1]."""

    def __init__(self, config, dt: float) -> None:
        self.dt = dt
        self.cruise = AdaptiveCruise(config.time_gap_s, config.standstill_gap_m, config.comfort_decel_mps2)
        self.fallbacks = 0
        self.solve_times: list[float] = []

    def reset(self) -> None:
        self.cruise.reset()

    def step(self, state: EgoState, reference: Reference) -> Actuation:
        start = time.perf_counter()
        course = math.atan(reference.d_dot / max(state.speed, 1.0))
        steering = self.LATERAL_GAIN * (reference.d - state.d) + self.HEADING_GAIN * (course - state.heading)
        steering = max(-0.2, min(0.2, steering))
        acceleration = self.cruise.update(state.speed, reference.set_speed, reference.leaders, self.dt)
        self.solve_times.append(time.perf_counter() - start)
        return Actuation(acceleration=acceleration, steering=steering)


if __name__ == "__main__":
    import stack

    config = stack.build_config(
        {
            "planner": {"agent": "mobil"},
            "controller": {"type": f"{Path(__file__).resolve()}:HeadingPD"},
            "highway": {"duration": 10},
        }
    )
    result = stack.run_episode(config, episode=0)
    print(f"one 10-s episode: mean speed {result.mean_speed:.1f} m/s, {result.lane_changes} lane changes")
