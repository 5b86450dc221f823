"""Lane-change MPC in CasADi, in three parts (as openpilot's lateral MPC):

1. symbolic model: `controllers.bicycle.symbolic_lane_model` (the plant's own equations);
2. problem builder: `build_problem(settings, dt)` -> a CasADi Function (Opti + IPOPT) mapping
   (state, references over the horizon, previous input, curvature, initial guesses) to the optimal
   inputs and states;
3. runtime wrapper: `MPCTracker`, which warm-starts from the last solution shifted by one tick,
   exposes `status` and `solve_time`, and falls back to a PID tracker (counting `fallbacks`) when
   the solve fails (no convergence within `max_iterations`) or returns anything non-finite; it never
   hands NaN to the plant. Only the solver's own outcome decides: the wall-clock time a solve took
   is measured and reported (`solve_times`, `slow_solves` above `max_solve_ms`), never used, so the
   same seed drives the same way on an idle and on a loaded machine.

Cost per step: lateral and heading errors to the reference, speed error to the adaptive cruise's
speed profile, input magnitudes, steering rate and jerk. Constraints: steering and steering rate,
acceleration, and |a_y| = v^2 sin(beta) / (L/2) <= the comfort bound.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from controllers.bicycle import LENGTH, symbolic_lane_model
from controllers.config import MPCSettings
from controllers.tracker import Controller
from records import Actuation, EgoState, Reference


def build_problem(settings: MPCSettings, dt: float) -> ca.Function:
    """The horizon-`settings.horizon` NLP as a Function:
    (x0[3], d_ref[N+1], psi_ref[N+1], v_ref[N+1], u_prev[2], curvature, X_guess[3,N+1], U_guess[2,N])
    -> (U[2,N], X[3,N+1])."""
    n, s = settings.horizon, settings
    model = symbolic_lane_model()
    opti = ca.Opti()
    states, inputs = opti.variable(3, n + 1), opti.variable(2, n)
    x0, u_prev, curvature = opti.parameter(3), opti.parameter(2), opti.parameter()
    d_ref, psi_ref, v_ref = opti.parameter(n + 1), opti.parameter(n + 1), opti.parameter(n + 1)
    opti.subject_to(states[:, 0] == x0)
    cost: ca.MX | int = 0
    for k in range(n):
        opti.subject_to(states[:, k + 1] == model(states[:, k], inputs[:, k], curvature, dt))
        previous = u_prev if k == 0 else inputs[:, k - 1]
        cost += s.weight_lateral * (states[0, k + 1] - d_ref[k + 1]) ** 2
        cost += s.weight_heading * (states[1, k + 1] - psi_ref[k + 1]) ** 2
        cost += s.weight_speed * (states[2, k + 1] - v_ref[k + 1]) ** 2
        cost += s.weight_acceleration * inputs[0, k] ** 2 + s.weight_steering * inputs[1, k] ** 2
        cost += s.weight_steering_rate * (inputs[1, k] - previous[1]) ** 2
        cost += s.weight_jerk * (inputs[0, k] - previous[0]) ** 2
        opti.subject_to(
            opti.bounded(-s.max_steering_rate * dt, inputs[1, k] - previous[1], s.max_steering_rate * dt)
        )
        beta = ca.atan(0.5 * ca.tan(inputs[1, k]))
        lateral_acceleration = states[2, k] ** 2 * ca.sin(beta) / (LENGTH / 2)
        opti.subject_to(
            opti.bounded(-s.max_lateral_acceleration, lateral_acceleration, s.max_lateral_acceleration)
        )
    opti.subject_to(opti.bounded(-s.max_steering, inputs[1, :], s.max_steering))
    opti.subject_to(opti.bounded(-s.max_deceleration, inputs[0, :], s.max_acceleration))
    opti.minimize(cost)
    opti.solver(
        "ipopt",
        {"print_time": False, "error_on_fail": False},
        {
            "print_level": 0,
            "sb": "yes",
            "max_iter": s.max_iterations,
            "tol": 1e-6,
            "warm_start_init_point": "yes",
            "mu_init": 1e-3,
        },
    )
    return opti.to_function(
        "lane_change_mpc",
        [x0, d_ref, psi_ref, v_ref, u_prev, curvature, states, inputs],
        [inputs, states],
    )


class MPCTracker:
    """Runtime wrapper: warm start, status, solve time, fallback. Same verb as the PID tracker."""

    def __init__(self, settings: MPCSettings, dt: float, fallback: Controller) -> None:
        self.settings = settings
        self.dt = dt
        self.solver = build_problem(settings, dt)
        self.fallback = fallback
        self.fallbacks = 0
        self.slow_solves = 0
        self.solve_times: list[float] = []
        self.reset()

    def reset(self) -> None:
        self.fallback.reset()
        self.states: np.ndarray | None = None
        self.inputs = np.zeros((2, self.settings.horizon))
        self.last_input = np.zeros(2)
        self.status = "idle"
        self.solve_time = 0.0

    def _references(
        self, state: EgoState, reference: Reference, acceleration: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = self.settings.horizon
        preview = reference.preview(n, self.dt)
        d = np.array([reference.d] + [p[0] for p in preview])
        speed = max(state.speed, 1.0)
        d_dot = np.array([reference.d_dot] + [p[1] for p in preview])
        psi = np.arcsin(np.clip(d_dot / speed, -0.5, 0.5))
        v = np.clip(
            state.speed + acceleration * self.dt * np.arange(n + 1),
            0.0,
            max(reference.set_speed, state.speed),
        )
        return d, psi, v

    def _guess(self, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.states is None:
            return np.tile(x0[:, None], (1, self.settings.horizon + 1)), self.inputs
        states = np.hstack([self.states[:, 1:], self.states[:, -1:]])
        states[:, 0] = x0
        return states, np.hstack([self.inputs[:, 1:], self.inputs[:, -1:]])

    def step(self, state: EgoState, reference: Reference) -> Actuation:
        backup = self.fallback.step(state, reference)
        x0 = np.array([state.d, state.heading, state.speed])
        d_ref, psi_ref, v_ref = self._references(state, reference, backup.acceleration)
        states_guess, inputs_guess = self._guess(x0)
        start = time.perf_counter()
        try:
            inputs, states = self.solver(
                x0, d_ref, psi_ref, v_ref, self.last_input, state.curvature, states_guess, inputs_guess
            )
            inputs, states = np.array(inputs), np.array(states)
            stats = self.solver.stats()
            self.status = stats.get("return_status", "unknown")
            success = bool(stats.get("success", False))
        except RuntimeError as error:
            inputs = states = None
            self.status, success = f"error: {error}".splitlines()[0], False
        self.solve_time = time.perf_counter() - start
        self.solve_times.append(self.solve_time)
        self.slow_solves += self.solve_time * 1e3 > self.settings.max_solve_ms
        usable = (
            success and inputs is not None and np.all(np.isfinite(inputs)) and np.all(np.isfinite(states))
        )
        if usable:
            self.inputs, self.states = inputs, states
            command = Actuation(acceleration=float(inputs[0, 0]), steering=float(inputs[1, 0]))
        else:
            self.fallbacks += 1
            self.states = None
            command = backup
            if not (math.isfinite(command.acceleration) and math.isfinite(command.steering)):
                command = Actuation(0.0, 0.0)
        self.last_input = np.array([command.acceleration, command.steering])
        return command
