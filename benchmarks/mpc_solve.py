"""MPC solve time per tick, the real-time iteration (`rti`, the default) and sqpmethod + qrqp
(`sqp`) against IPOPT, on the same recorded lane changes.

Each prediction model records the solver arguments of every tick of left lane changes on its own
plant driven by `rti` (straight road at 22 m/s, 1000 m bend at 35 m/s, the `track` setup); every
recorded tick is then solved by the three solvers back to back, in one sitting, and the CPU time of
each solve (`time.process_time`) is kept. Prints p50 / p95 per solver, the ratios to IPOPT,
failures and the largest first-steering-move difference to IPOPT [rad].

.venv/bin/python benchmarks/mpc_solve.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from controllers.config import MPCSettings
from controllers.mpc import MPCTracker
from controllers.mpc_problem import Problem, build_problem
from stack.apps.track import run_maneuver
from stack.settings.run import ControllerConfig

DT = 1 / 15
CASES = (("straight", 22.0), ("bend-1000", 35.0))


def record(settings: MPCSettings) -> list[tuple[np.ndarray, ...]]:
    """Solver arguments of every tick of the CASES' left lane changes on the model's plant."""
    calls: list[tuple[np.ndarray, ...]] = []
    MPCTracker.recording = calls
    try:
        for road, speed in CASES:
            run_maneuver("mpc", ControllerConfig(mpc=settings), road, settings.model, speed, "left", 5.0, DT)
    finally:
        MPCTracker.recording = None
    return calls


def timed_move(problem: Problem, arguments: tuple[np.ndarray, ...]) -> tuple[float, float, bool]:
    """(CPU seconds, first steering move [rad], success) of one solve."""
    start = time.process_time()
    w = problem.solver(*arguments)[0]
    elapsed = time.process_time() - start
    return elapsed, float(problem.unpack(np.array(w))[0][1, 0]), bool(problem.solver.stats()["success"])


SOLVERS = ("rti", "sqp", "ipopt")
HEADER = (
    "| model | ticks | rti p50 / p95 ms | sqp p50 / p95 ms | ipopt p50 / p95 ms | rti / ipopt p50, p95 "
    "| sqp / ipopt p50, p95 | failures rti / sqp / ipopt | max first-move diff to ipopt rad rti, sqp |"
)


def compare(model: str, repeats: int) -> str:
    """The table row of one prediction model: the three solvers on the same recorded ticks."""
    settings = MPCSettings.model_validate({"model": model})
    calls = record(settings)
    problems = {name: build_problem(settings.model_copy(update={"solver": name}), DT) for name in SOLVERS}
    times: dict[str, list[float]] = {name: [] for name in problems}
    failures = dict.fromkeys(problems, 0)
    difference = dict.fromkeys(problems, 0.0)
    for _ in range(repeats):
        for arguments in calls:
            moves = {}
            for name, problem in problems.items():
                elapsed, moves[name], success = timed_move(problem, arguments)
                times[name].append(elapsed * 1e3)
                failures[name] += not success
            for name in problems:
                difference[name] = max(difference[name], abs(moves[name] - moves["ipopt"]))
    rti, sqp, ipopt = (np.percentile(times[name], [50, 95]) for name in SOLVERS)
    cells = [f"{model} | {len(calls)}", *(f"{q[0]:.2f} / {q[1]:.2f}" for q in (rti, sqp, ipopt))]
    cells += [f"{q[0] / ipopt[0]:.2f}, {q[1] / ipopt[1]:.2f}" for q in (rti, sqp)]
    cells += [" / ".join(str(failures[name]) for name in SOLVERS)]
    cells += [f"{difference['rti']:.1e}, {difference['sqp']:.1e}"]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="passes over the recording")
    repeats = parser.parse_args().repeats
    print(HEADER)
    print("|---" * 9 + "|")
    for model in ("kinematic", "dynamic"):
        print(compare(model, repeats), flush=True)


if __name__ == "__main__":
    main()
