"""Problem builder of the lane-change MPC: the horizon as one NLP in plain CasADi SX, laid out
stage by stage (multiple shooting) so every constraint and cost term couples one stage only, the
QP is banded and a warm start is a shift by one stage.

The state is augmented with the previous input, x~ = (x, a_prev, delta_prev), so steering rate and
jerk are stage-local. Decision vector w = (x~_0, u_0, slacks_0, ..., x~_{N-1}, u_{N-1}, slacks_{N-1},
x~_N); x~_0 is pinned to the measured state and last input by its bounds. Constraints g, per stage
k: x~_{k+1} = (f(x_k, u_k), u_k), then the steering rate and the lateral acceleration, each -+ its
slack. Parameters p = (d_ref[N+1], psi_ref[N+1], v_ref[N+1], curvature). Hard bounds: steering and
acceleration (an input inside them always exists). Soft bounds: the steering rate
|delta_k - delta_{k-1}| / dt and the lateral acceleration relative to the lane,
a_y = v_{k+1} (psi_{k+1} - psi_k) / dt (what `stack.core.metrics` measures), each widened by a
non-negative slack priced `weight_slack` s^2, so no start state makes the problem infeasible. (No
linear term: qrqp starts from the unconstrained minimiser, and a linear price sends it through
hundreds of active-set changes per QP.)

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
"""(steering rate [rad/s], lateral acceleration [m/s^2])."""


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
    signature) and the layout helpers that pack and unpack its vectors. The start state enters
    through the bounds of x_0 (`bounds`), the references and curvature through p (`parameters`).
    `pin` and `advance` are the per-tick vector operations as CasADi functions on `ca.DM`, and
    `constants` the DMs of (lbg, ubg, lam_x0, lam_g0): a tick converts no long numpy array."""

    solver: Solver
    horizon: int
    n_states: int
    stage_lower: np.ndarray
    stage_upper: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    pin: ca.Function
    advance: ca.Function
    constants: tuple[ca.DM, ...]

    @property
    def n_augmented(self) -> int:
        """States per stage with the previous input appended."""
        return self.n_states + N_INPUTS

    @property
    def stage(self) -> int:
        """Decision variables per stage (x_k, u_k, slacks_k)."""
        return self.n_augmented + N_INPUTS + N_SLACKS

    @property
    def stage_constraints(self) -> int:
        return self.n_augmented + 2 * N_SLACKS

    def bounds(self, x0: np.ndarray, u_prev: np.ndarray) -> tuple[ca.DM, ca.DM]:
        """(lbx, ubx) with x_0 pinned to the start state and the last input."""
        lower, upper = self.pin(np.concatenate([x0, u_prev]))
        return lower, upper

    def first_input(self, w: ca.DM) -> tuple[float, float]:
        """(acceleration [m/s^2], steering [rad]) of the first stage of a decision vector."""
        return float(w[self.n_augmented]), float(w[self.n_augmented + 1])

    def initial_guess(self, x0: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        """Every state the start state, inputs the last input, slacks zero: a cold start."""
        start = np.concatenate([x0, u_prev])
        stage = np.concatenate([start, u_prev, np.zeros(N_SLACKS)])
        return np.concatenate([np.tile(stage, self.horizon), start])

    def unpack(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(inputs [2, N], states x_0..x_N [n_states, N+1]) of a decision vector."""
        w = np.asarray(w, dtype=float).ravel()
        stages = w[: -self.n_augmented].reshape(self.horizon, self.stage).T
        states = np.hstack([stages[: self.n_states], w[-self.n_augmented :, None][: self.n_states]])
        return stages[self.n_augmented : self.n_augmented + N_INPUTS], states

    @staticmethod
    def parameters(references: tuple[np.ndarray, np.ndarray, np.ndarray], curvature: float) -> np.ndarray:
        """p of the solver: (d, psi, v) references over N+1 ticks, curvature [1/m]."""
        return np.concatenate([*references, [curvature]])


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


def vector_functions(
    lower: np.ndarray, upper: np.ndarray, augmented: int, stage: int
) -> tuple[ca.Function, ca.Function]:
    """(pin(start) -> (lbx, ubx) with the first `augmented` entries the start, advance(w) -> w
    shifted one `stage` ahead) as CasADi functions."""
    start, w = ca.SX.sym("start", augmented), ca.SX.sym("w", len(lower))
    pinned = [ca.vertcat(start, ca.DM(bound[augmented:])) for bound in (lower, upper)]
    pin = ca.Function("pin", [start], pinned)
    advance = ca.Function("advance", [w], [ca.vertcat(w[stage:], w[-stage:])])
    return pin, advance


@lru_cache(maxsize=8)
def build_problem(settings: MPCSettings, dt: float) -> Problem:
    """The horizon-`settings.horizon` lane-change NLP for a control period of `dt` [s] (cached:
    the same settings and period give the same, stateless, problem)."""
    s, n = settings, settings.horizon
    model, nx = prediction_model(settings)
    d_ref, psi_ref, v_ref = (ca.SX.sym(name, n + 1) for name in ("d_ref", "psi_ref", "v_ref"))
    curvature = ca.SX.sym("curvature")
    augmented = nx + N_INPUTS
    states = [ca.SX.sym(f"x{k}", augmented) for k in range(n + 1)]
    controls = [ca.SX.sym(f"u{k}", N_INPUTS + N_SLACKS) for k in range(n)]
    cost, constraints, variables = ca.SX(0), [], []
    for k, (x, control) in enumerate(zip(states, controls, strict=False)):
        u, previous, rate_slack, ay_slack = control[:2], x[nx:], control[2], control[3]
        after = model(x[:nx], u, curvature, dt)
        rate = (u[1] - previous[1]) / dt
        lateral_acceleration = after[2] * (after[1] - x[1]) / dt
        constraints += [
            ca.vertcat(after, u) - states[k + 1],
            rate - rate_slack,
            rate + rate_slack,
            lateral_acceleration - ay_slack,
            lateral_acceleration + ay_slack,
        ]
        variables += [x, control]
        if k > 0:
            cost += s.weight_lateral * (x[0] - d_ref[k]) ** 2
            cost += s.weight_heading * (x[1] - psi_ref[k]) ** 2
            cost += s.weight_speed * (x[2] - v_ref[k]) ** 2
        cost += s.weight_acceleration * u[0] ** 2 + s.weight_steering * u[1] ** 2
        cost += s.weight_steering_rate * (u[1] - previous[1]) ** 2
        cost += s.weight_jerk * (u[0] - previous[0]) ** 2
        cost += s.weight_slack * (rate_slack**2 + ay_slack**2)
    last = states[n]
    cost += s.weight_lateral * (last[0] - d_ref[n]) ** 2 + s.weight_heading * (last[1] - psi_ref[n]) ** 2
    cost += s.weight_speed * (last[2] - v_ref[n]) ** 2
    nlp = {
        "x": ca.vertcat(*variables, last),
        "p": ca.vertcat(d_ref, psi_ref, v_ref, curvature),
        "f": cost,
        "g": ca.vertcat(*constraints),
    }
    inf, rate_bound, ay_bound = np.inf, s.max_steering_rate, s.max_lateral_acceleration
    stage_lower = np.array([-inf] * augmented + [-s.max_deceleration, -s.max_steering, 0.0, 0.0])
    stage_upper = np.array([inf] * augmented + [s.max_acceleration, s.max_steering, inf, inf])
    free = np.full(augmented, inf)
    lower, upper = np.tile(stage_lower, n), np.tile(stage_upper, n)
    pin, advance = vector_functions(
        np.concatenate([lower, -free]), np.concatenate([upper, free]), augmented, len(stage_lower)
    )
    lbg = np.tile([0.0] * augmented + [-inf, -rate_bound, -inf, -ay_bound], n)
    ubg = np.tile([0.0] * augmented + [rate_bound, inf, ay_bound, inf], n)
    zeros = (ca.DM.zeros(len(lower) + augmented), ca.DM.zeros(len(lbg)))
    return Problem(
        solver=make_solver(settings, nlp),
        horizon=n,
        n_states=nx,
        stage_lower=stage_lower,
        stage_upper=stage_upper,
        lbg=lbg,
        ubg=ubg,
        pin=pin,
        advance=advance,
        constants=(ca.DM(lbg), ca.DM(ubg), *zeros),
    )
