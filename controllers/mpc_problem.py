"""Problem builder of the lane-change MPC: the horizon as one NLP in plain CasADi SX, laid out
stage by stage (multiple shooting) so every constraint and cost term couples neighbouring stages
only, the QP is banded and a warm start is a shift by one stage.

The measured state x_0 and the last input u_-1 are parameters, not variables, so the bounds are
constant. Decision vector w = (z_0, ..., z_{N-1}) with z_k = (u_k, e_k, x_{k+1}): the input
(acceleration, steering), the comfort-bound excesses and the state it leads to. Constraints g, per
stage k: x_{k+1} = f(x_k, u_k), then the steering rate and the lateral acceleration, each minus its
excess. Parameters p = (d_ref[N+1], psi_ref[N+1], v_ref[N+1], curvature, x_0, u_-1). Hard bounds:
steering and acceleration (an input inside them always exists). Soft bounds: the steering rate
|delta_k - delta_{k-1}| / dt and the lateral acceleration relative to the lane,
a_y = v_{k+1} (psi_{k+1} - psi_k) / dt (what `stack.loop.metrics` measures): the quantity minus a
free excess e must lie inside the bound, and e is priced `weight_slack` e^2, so no start state
makes the problem infeasible (the same optimum as a non-negative slack on each side, with one
constraint row instead of two). (No linear term: qrqp starts from the unconstrained minimiser, and
a linear price sends it through hundreds of active-set changes per QP.)

Solvers (`MPCSettings.solver`): `rti`, one Gauss-Newton SQP step per tick (`controllers.mpc_rti`);
`sqp`, `sqpmethod` + `qrqp` to convergence with the same Gauss-Newton Hessian (the cost's, constant:
the same optimum as the exact Hessian, 0.6 ms a tick less on the dynamic model); `ipopt`, the
reference. Built problems are cached per process, keyed by settings and period: an episode's
controller reuses the last episode's solver instead of expanding the NLP again (0.05-0.15 s).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Protocol

import casadi as ca
import numpy as np

from controllers.bicycle import symbolic_dynamic_lane_model, symbolic_lane_model
from controllers.config import MPCSettings
from controllers.mpc_rti import QP_OPTIONS, RealTimeIteration

N_INPUTS = 2
"""(acceleration [m/s^2], steering [rad])."""
N_SLACKS = 2
"""Comfort-bound excesses: (steering rate [rad/s], lateral acceleration [m/s^2])."""


def prediction_model(settings: MPCSettings) -> tuple[ca.Function, int]:
    """(f(state, input, curvature, dt) -> next state, number of states) of `settings.model`."""
    if settings.model == "dynamic":
        model = symbolic_dynamic_lane_model(
            settings.mass,
            settings.yaw_inertia,
            settings.cornering_stiffness_front,
            settings.cornering_stiffness_rear,
        )
        return model, 5
    return symbolic_lane_model(), 3


class Solver(Protocol):
    """CasADi's nlpsol call signature and `stats()`; a `ca.Function` or a `RealTimeIteration`."""

    def __call__(self, *arguments: Any) -> Any: ...

    def stats(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class Problem:
    """The built NLP: `solver(x0, p, lbx, ubx, lbg, ubg, lam_x0, lam_g0)` (CasADi's nlpsol
    signature) and the layout helpers that pack and unpack its vectors. The start state and last
    input enter through p (`parameters`); `constants` are the DMs of (lbx, ubx, lbg, ubg, lam_x0,
    lam_g0), the same every tick, and `advance` shifts a decision vector on `ca.DM`: a tick converts
    no long numpy array."""

    solver: Solver
    horizon: int
    n_states: int
    constants: tuple[ca.DM, ...]
    advance: ca.Function

    @property
    def stage(self) -> int:
        """Decision variables per stage (u_k, e_k, x_{k+1})."""
        return N_INPUTS + N_SLACKS + self.n_states

    def initial_guess(self, x0: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        """Every state the start state, inputs the last input, excesses zero: a cold start."""
        return np.tile(np.concatenate([u_prev, np.zeros(N_SLACKS), x0]), self.horizon)

    def unpack(self, w: Any) -> tuple[np.ndarray, np.ndarray]:
        """(inputs [2, N], states x_1..x_N [n_states, N]) of a decision vector."""
        stages = np.asarray(w, dtype=float).ravel().reshape(self.horizon, self.stage).T
        return stages[:N_INPUTS], stages[N_INPUTS + N_SLACKS :]

    @staticmethod
    def first_input(w: ca.DM) -> tuple[float, float]:
        """(acceleration [m/s^2], steering [rad]) of the first stage of a decision vector."""
        acceleration, steering = w.nonzeros()[:2]
        return acceleration, steering

    @staticmethod
    def parameters(
        references: tuple[np.ndarray, np.ndarray, np.ndarray],
        curvature: float,
        x0: np.ndarray,
        u_prev: np.ndarray,
    ) -> np.ndarray:
        """p of the solver: (d, psi, v) references over N+1 ticks, curvature [1/m], start state,
        last input."""
        return np.concatenate([*references, [curvature], x0, u_prev])


def _solver_plugin(settings: MPCSettings) -> tuple[str, dict]:
    """The nlpsol plugin and options of `settings.solver`; only iteration counts bound a solve."""
    if settings.solver == "ipopt":
        return "ipopt", {
            "expand": True,
            "print_time": False,
            "error_on_fail": False,
            "ipopt": {
                "print_level": 0,
                "sb": "yes",
                "max_iter": settings.max_iterations,
                "tol": 1e-6,
                "warm_start_init_point": "yes",
                "mu_init": 1e-3,
            },
        }
    return "sqpmethod", {
        "expand": True,
        "qpsol": "qrqp",
        "qpsol_options": {**QP_OPTIONS, "max_iter": settings.max_qp_iterations},
        "print_header": False,
        "print_iteration": False,
        "print_status": False,
        "print_time": False,
        "error_on_fail": False,
        "max_iter": settings.max_iterations,
    }


def gauss_newton(nlp: dict[str, ca.SX]) -> ca.Function:
    """sqpmethod's `hess_lag` option: the cost's Hessian (constant) times the cost multiplier,
    without the constraints' curvature."""
    w, p = nlp["x"], nlp["p"]
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", nlp["g"].numel())
    hessian = lam_f * ca.hessian(nlp["f"], w)[0]
    return ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hessian])


def make_solver(settings: MPCSettings, nlp: dict[str, ca.SX]) -> Solver:
    """The solver `settings.solver` of the NLP `nlp`."""
    if settings.solver == "rti":
        return RealTimeIteration(nlp, settings.max_qp_iterations)
    plugin, options = _solver_plugin(settings)
    if plugin == "sqpmethod":
        options["hess_lag"] = gauss_newton(nlp)
    return ca.nlpsol("lane_change_mpc", plugin, nlp, options)


@lru_cache(maxsize=8)
def build_problem(settings: MPCSettings, dt: float) -> Problem:
    """The horizon-`settings.horizon` lane-change NLP for a control period of `dt` [s] (cached:
    the same settings and period give the same, stateless, problem)."""
    s, n = settings, settings.horizon
    model, nx = prediction_model(settings)
    d_ref, psi_ref, v_ref = (ca.SX.sym(name, n + 1) for name in ("d_ref", "psi_ref", "v_ref"))
    curvature, x0, u_prev = ca.SX.sym("curvature"), ca.SX.sym("x0", nx), ca.SX.sym("u_prev", N_INPUTS)
    stages = [ca.SX.sym(f"z{k}", N_INPUTS + N_SLACKS + nx) for k in range(n)]
    cost, constraints, x, previous = ca.SX(0), [], x0, u_prev
    for k, z in enumerate(stages):
        u, rate_excess, ay_excess, after = z[:2], z[2], z[3], z[4:]
        predicted = model(x, u, curvature, dt)
        rate = (u[1] - previous[1]) / dt
        lateral_acceleration = predicted[2] * (predicted[1] - x[1]) / dt
        constraints += [predicted - after, rate - rate_excess, lateral_acceleration - ay_excess]
        cost += s.weight_lateral * (after[0] - d_ref[k + 1]) ** 2
        cost += s.weight_heading * (after[1] - psi_ref[k + 1]) ** 2
        cost += s.weight_speed * (after[2] - v_ref[k + 1]) ** 2
        cost += s.weight_acceleration * u[0] ** 2 + s.weight_steering * u[1] ** 2
        cost += s.weight_steering_rate * (u[1] - previous[1]) ** 2
        cost += s.weight_jerk * (u[0] - previous[0]) ** 2
        cost += s.weight_slack * (rate_excess**2 + ay_excess**2)
        x, previous = after, u
    nlp = {
        "x": ca.vertcat(*stages),
        "p": ca.vertcat(d_ref, psi_ref, v_ref, curvature, x0, u_prev),
        "f": cost,
        "g": ca.vertcat(*constraints),
    }
    inf, stage = np.inf, N_INPUTS + N_SLACKS + nx
    lower = np.tile([-s.max_deceleration, -s.max_steering] + [-inf] * (N_SLACKS + nx), n)
    upper = np.tile([s.max_acceleration, s.max_steering] + [inf] * (N_SLACKS + nx), n)
    rate_bound, ay_bound = s.max_steering_rate, s.max_lateral_acceleration
    lbg = np.tile([0.0] * nx + [-rate_bound, -ay_bound], n)
    ubg = np.tile([0.0] * nx + [rate_bound, ay_bound], n)
    w = ca.SX.sym("w", n * stage)
    return Problem(
        solver=make_solver(settings, nlp),
        horizon=n,
        n_states=nx,
        constants=tuple(ca.DM(v) for v in (lower, upper, lbg, ubg, np.zeros(len(lower)), np.zeros(len(lbg)))),
        advance=ca.Function("advance", [w], [ca.vertcat(w[stage:], w[-stage:])]),
    )
