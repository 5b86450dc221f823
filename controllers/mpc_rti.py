"""Real-time iteration (acados' RTI) for the lane-change NLP: one Gauss-Newton SQP step per tick,
taken in full from the warm start (the last solution shifted by one stage), with CasADi's `qrqp`
on the QP.

The cost is a sum of squares of terms linear in the decision vector, so its Hessian is constant;
Gauss-Newton leaves out the constraints' curvature, so the QP's Hessian is computed once at build
time. Per tick: one call of an expanded SX function (cost gradient, constraint Jacobian and the
QP's bounds at the guess; compiled to C when the machine can, `controllers.casadi_codegen`) and one
`qrqp` solve. A guess that is already optimal (zero cost gradient, feasible: lane keeping exactly
at the steady state) is kept without a QP, as sqpmethod's convergence test before its first
iteration does: qrqp can cycle between equivalent active sets on that degenerate QP. The step
succeeds when `qrqp` converges within `max_iterations` active-set iterations, or when its last
iterate meets the QP's optimality conditions to `QP_TOLERANCE` anyway, and the result is finite.
The QP's own outcome, never the clock, decides a fallback.
"""

from __future__ import annotations

from typing import Any

import casadi as ca

from controllers.casadi_codegen import compiled

QP_OPTIONS = {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False}
QP_TOLERANCE = 1e-8
"""Largest stationarity, bound violation and complementarity residual of an accepted QP step
(qrqp's own tolerances)."""


def optimality(hessian: ca.DM, jacobian: ca.Sparsity) -> ca.Function:
    """`residual(dx, lam_x, lam_a, g, A, lba, uba, lbx, ubx)`: the largest KKT residual of the QP
    min 1/2 dx' H dx + g' dx s.t. lba <= A dx <= uba, lbx <= dx <= ubx, with CasADi's multiplier
    signs (positive at an upper bound)."""
    n, m = jacobian.size2(), jacobian.size1()
    dx, lam_x, g, lbx, ubx = (ca.SX.sym(name, n) for name in ("dx", "lam_x", "g", "lbx", "ubx"))
    lam_a, lba, uba = (ca.SX.sym(name, m) for name in ("lam_a", "lba", "uba"))
    a = ca.SX.sym("A", jacobian)
    z, lam, lower, upper = (
        ca.vertcat(a @ dx, dx),
        ca.vertcat(lam_a, lam_x),
        ca.vertcat(lba, lbx),
        ca.vertcat(uba, ubx),
    )
    residuals = [
        ca.norm_inf(hessian @ dx + g + a.T @ lam_a + lam_x),
        ca.mmax(ca.fmax(ca.fmax(lower - z, z - upper), 0)),
        ca.mmax(ca.fmax(lam, 0) * ca.fmin(upper - z, 1) + ca.fmax(-lam, 0) * ca.fmin(z - lower, 1)),
    ]
    inputs = [dx, lam_x, lam_a, g, a, lba, uba, lbx, ubx]
    return ca.Function("rti_optimality", inputs, [ca.mmax(ca.vertcat(*residuals))])


class RealTimeIteration:
    """One SQP step on `nlp` (CasADi's dict x, p, f, g) per call, with nlpsol's call signature
    `(x0, p, lbx, ubx, lbg, ubg, lam_x0, lam_g0) -> [x]` (multipliers ignored: primal warm start)
    and `stats()` with `success` and `return_status`, so the runtime treats it as any solver."""

    def __init__(self, nlp: dict[str, ca.SX], max_iterations: int) -> None:
        w, p, g = nlp["x"], nlp["p"], nlp["g"]
        bounds = [ca.SX.sym(name, w.numel()) for name in ("lbx", "ubx")]
        bounds += [ca.SX.sym(name, g.numel()) for name in ("lbg", "ubg")]
        jacobian, gradient = ca.jacobian(g, w), ca.gradient(nlp["f"], w)
        qp_bounds = [bounds[2] - g, bounds[3] - g, bounds[0] - w, bounds[1] - w]
        infeasibility = ca.mmax(
            ca.fmax(ca.vertcat(qp_bounds[0], qp_bounds[2], -qp_bounds[1], -qp_bounds[3]), 0)
        )
        self.linearise = compiled(
            ca.Function(
                "rti_linearise",
                [w, p, *bounds],
                [gradient, jacobian, *qp_bounds, ca.fmax(ca.norm_inf(gradient), infeasibility)],
            )
        )
        hessian = ca.hessian(nlp["f"], w)[0]
        self.hessian = ca.Function("rti_hessian", [], [hessian])()["o0"]
        qp = {"h": self.hessian.sparsity(), "a": jacobian.sparsity()}
        options = {**QP_OPTIONS, "max_iter": max_iterations}
        self.qp = ca.conic("rti_qp", "qrqp", qp, options)
        self.optimality = optimality(self.hessian, jacobian.sparsity())
        n, m = jacobian.size2(), jacobian.size1()
        # qrqp's (x0, lam_x0, lam_a0, q, p): a cold QP from a zero step, no parameters.
        self.qp_start = (ca.DM.zeros(n), ca.DM.zeros(n), ca.DM.zeros(m), ca.DM(), ca.DM())
        self._stats: dict[str, Any] = {"success": False, "return_status": "idle"}

    def __call__(self, x0: Any, p: Any, lbx: Any, ubx: Any, lbg: Any, ubg: Any, *_: Any) -> list[ca.DM]:
        """[the decision vector after one full SQP step from `x0`]."""
        guess = x0 if isinstance(x0, ca.DM) else ca.DM(x0)
        gradient, jacobian, lba, uba, lower, upper, residual = self.linearise(guess, p, lbx, ubx, lbg, ubg)
        if residual <= QP_TOLERANCE:
            self._stats = {"success": True, "return_status": "Solve_Succeeded"}
            return [guess]
        qp_bounds = (lba, uba, lower, upper)
        step, _, lam_a, lam_x = self.qp(self.hessian, gradient, jacobian, *qp_bounds, *self.qp_start)
        stats = self.qp.stats()
        success, status = bool(stats["success"]), "Solve_Succeeded"
        if not success:
            residual = self.optimality(step, lam_x, lam_a, gradient, jacobian, *qp_bounds)
            success = bool(residual <= QP_TOLERANCE)
            status = "Solved_At_Iteration_Limit" if success else f"QP: {stats['return_status']}"
        self._stats = {"success": success, "return_status": status}
        return [guess + step]

    def stats(self) -> dict[str, Any]:
        """`success` and `return_status` of the last call's QP."""
        return self._stats
