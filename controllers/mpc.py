"""Lane-change MPC in CasADi, in three parts (as openpilot's lateral MPC):

1. symbolic model: `controllers.bicycle` (the plant's own equations, kinematic or dynamic bicycle,
   `MPCSettings.model`);
2. problem builder: `controllers.mpc_problem.build_problem(settings, dt)`, the stage-wise NLP with
   soft comfort bounds, solved by one Gauss-Newton SQP step per tick (`rti`, the default), by
   `sqpmethod` + `qrqp` to convergence (`sqp`) or by IPOPT (`MPCSettings.solver`);
3. runtime wrapper: `MPCTracker`, which warm-starts from the last solution shifted by one tick
   (primal only: shifted multipliers made qrqp's active-set start fail, 34 fallbacks in one
   35 m/s bend maneuver against 1 without), exposes `status` and `solve_time`, and falls back to a PID tracker
   (counting `fallbacks`) when the solve fails (rti: its QP, within `max_qp_iterations`; sqp and
   ipopt: no convergence within `max_iterations`) or returns
   anything non-finite; it never hands NaN to the plant. The vectors of a tick stay CasADi DMs
   (converting eight numpy arrays cost 0.3 ms a tick). Only the solver's own outcome decides: the
   wall-clock time a solve took is measured and reported (`solve_times`, `slow_solves` above
   `max_solve_ms`), never used, so the same seed drives the same way on an idle and on a loaded
   machine.

Cost per step: lateral and heading errors to the reference, speed error to the adaptive cruise's
speed profile, input magnitudes, steering rate and jerk, comfort-bound violations.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from controllers.bicycle import LENGTH, YAW_POLE_SPEED
from controllers.config import MPCSettings
from controllers.mpc_problem import build_problem
from controllers.protocol import Controller
from records import Actuation, EgoState, Reference


def steady_steering(state: EgoState) -> float:
    """The steering [rad] that holds the ego's yaw rate in a steady turn (delta = atan(L r / v),
    neutral steer on both bicycles): the previous input of an episode's first solve, so a car
    that starts in a bend is not asked to unwind its steering first."""
    return math.atan(LENGTH * state.yaw_rate / max(state.speed, 1.0))


RK4_STABLE = 2.785
"""RK4's stability limit on the real axis, |lambda dt|."""


class MPCTracker:
    """Runtime wrapper: warm start, status, solve time, fallback. Same verb as the PID tracker.

    Below `crawl_speed` the dynamic model's one RK4 step per stage is unstable (its yaw pole
    -YAW_POLE_SPEED / v times dt leaves RK4's stability region: 3.7 m/s at 15 Hz), so there the
    MPC predicts with the kinematic bicycle, which the dynamic one approaches as tyre slip
    vanishes (2.58 cm RMS at 3 m/s on a 500 m bend with the dynamic prediction), and never
    accelerates beyond the adaptive cruise (it crept into a stopped leader before, found by
    `drivestack safety`)."""

    recording: list[tuple[ca.DM, ...]] | None = None
    """When a list, every solve's arguments are appended to it (to replay a run offline)."""

    def __init__(self, settings: MPCSettings, dt: float, fallback: Controller) -> None:
        self.settings = settings
        self.dt = dt
        self.cruising_problem = build_problem(settings, dt)
        self.crawling_problem = build_problem(settings.model_copy(update={"model": "kinematic"}), dt)
        self.problem = self.cruising_problem
        self.solver = self.problem.solver
        self.fallback = fallback
        dynamic = settings.model == "dynamic"
        self.crawl_speed = YAW_POLE_SPEED * dt / RK4_STABLE if dynamic else 0.0
        self.fallbacks = 0
        self.slow_solves = 0
        self.solve_times: list[float] = []
        self.reset()

    def reset(self) -> None:
        self.fallback.reset()
        self.guess: ca.DM | None = None
        self.last_input: np.ndarray | None = None
        self.status = "idle"
        self.solve_time = 0.0

    def _references(
        self, state: EgoState, reference: Reference, acceleration: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = self.settings.horizon
        d_preview, d_dot_preview = reference.preview(n, self.dt)
        d = np.concatenate([[reference.d], d_preview])
        speed = max(state.speed, 1.0)
        d_dot = np.concatenate([[reference.d_dot], d_dot_preview])
        psi = np.arcsin(np.clip(d_dot / speed, -0.5, 0.5))
        v = np.clip(
            state.speed + acceleration * self.dt * np.arange(n + 1),
            0.0,
            max(reference.set_speed, state.speed),
        )
        return d, psi, v

    def _start(self, state: EgoState) -> np.ndarray:
        """The model's start state: (d, psi, v) or (d, psi, v, v_y, r)."""
        full = np.array([state.d, state.heading, state.speed, state.lateral_speed, state.yaw_rate])
        return full[: self.problem.n_states]

    def _solve(self, arguments: tuple[ca.DM, ...]) -> tuple[bool, ca.DM | None]:
        """(success, decision vector) of one solve; keeps the solution shifted by one stage as the
        next tick's guess."""
        if self.recording is not None:
            self.recording.append(arguments)
        try:
            w = self.solver(*arguments)[0]
            stats = self.solver.stats()
        except RuntimeError as error:
            self.status = f"error: {error}".splitlines()[0]
            return False, None
        self.status = stats.get("return_status", "unknown")
        usable = bool(stats.get("success", False)) and bool(w.is_regular())
        if usable:
            self.guess = self.problem.advance(w)
        return usable, w

    def step(self, state: EgoState, reference: Reference) -> Actuation:
        backup = self.fallback.step(state, reference)
        crawling = state.speed < self.crawl_speed
        problem = self.crawling_problem if crawling else self.cruising_problem
        if problem is not self.problem:
            self.problem, self.solver, self.guess = problem, problem.solver, None
        x0 = self._start(state)
        references = self._references(state, reference, backup.acceleration)
        if self.last_input is None:
            self.last_input = np.array([0.0, steady_steering(state)])
        p = ca.DM(problem.parameters(references, state.curvature, x0, self.last_input))
        w0 = self.guess
        if w0 is None:
            w0 = ca.DM(problem.initial_guess(x0, self.last_input))
        arguments = (w0, p, *problem.constants)
        start = time.perf_counter()
        success, w = self._solve(arguments)
        self.solve_time = time.perf_counter() - start
        self.solve_times.append(self.solve_time)
        self.slow_solves += self.solve_time * 1e3 > self.settings.max_solve_ms
        if success and w is not None:
            acceleration, steering = problem.first_input(w)
            if crawling:
                acceleration = min(acceleration, backup.acceleration)
            command = Actuation(acceleration=acceleration, steering=steering)
        else:
            self.fallbacks += 1
            self.guess = None
            command = backup
            if not (math.isfinite(command.acceleration) and math.isfinite(command.steering)):
                command = Actuation(0.0, 0.0)
        self.last_input = np.array([command.acceleration, command.steering])
        return command
