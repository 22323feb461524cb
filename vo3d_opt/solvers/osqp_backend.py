"""OSQP through its own Python API, with one persistent solver per problem shape.

OSQP takes the :class:`~vo3d_opt.solvers.Standard` rows ``l <= C x <= u`` as they are. Every
entry of C and of P's upper triangle is stored (dense pattern), so problems of the same shape
share a sparsity pattern: the solver set up for the first is updated in place and warm-started
from its last answer for the next. Updates and solves go straight to the compiled solver
(``OSQP._solver``, the extension object behind ``OSQP.update``/``OSQP.solve``): the Python
wrapper costs tens of microseconds per call, more than OSQP itself on these problems.

OSQP 1.x prints "Polishing not needed" whatever ``verbose`` says when the optimum has no active
constraint (osqp/osqp#785). Such problems are answered before OSQP runs: when P is positive
definite and the unconstrained minimiser -P⁻¹q satisfies every constraint, it is the optimum.
"""
from __future__ import annotations

import numpy as np
import osqp

from vo3d_opt.formulations.problem import QP, Result
from vo3d_opt.solvers._sparse import dense_csc, triu_csc, triu_index
from vo3d_opt.solvers import Backend, Standard, make_result

#: Settings of every solver: tight tolerances, polishing, silence.
SETTINGS = dict(eps_abs=1e-7, eps_rel=1e-7, polishing=True, verbose=False, max_iter=10_000)
#: At most this many persistent solvers (one per shape); the cache is emptied when full.
MAX_CACHED = 64
#: OSQP's infinity: bounds beyond it are clipped to it.
INFTY = osqp.constant("OSQP_INFTY")

_STATUS = {
    osqp.SolverStatus.OSQP_SOLVED: "optimal",
    osqp.SolverStatus.OSQP_SOLVED_INACCURATE: "optimal",  # kept only if x is feasible
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE: "infeasible",
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE: "infeasible",
}


def unconstrained_optimum(std: Standard) -> np.ndarray | None:
    """-P⁻¹q when it satisfies every constraint and P is positive definite, else None."""
    try:
        x = np.linalg.solve(std.P, -std.q)
        if std.violation(x) > 0.0:
            return None
        np.linalg.cholesky(std.P)  # raises unless positive definite
    except np.linalg.LinAlgError:
        return None
    return x


class OsqpBackend(Backend):
    """OSQP with a polished, tightly converged answer; polygons only (no cones)."""

    name = "osqp"
    has_cones = False
    kind = "qp"
    checks_answers = True

    def __init__(self) -> None:
        self._solvers: dict[tuple[int, int], osqp.OSQP] = {}

    def _solve(self, qp: QP, std: Standard, warm_start: np.ndarray | None) -> Result:
        """``warm_start`` (shape (n,)) seeds OSQP's primal iterate."""
        if (x := unconstrained_optimum(std)) is not None:
            return Result(x, "optimal", self.name, "unconstrained optimum is feasible")
        return self._solve_osqp(std, warm_start)

    def _solve_osqp(self, std: Standard, warm_start: np.ndarray | None) -> Result:
        key = std.C.shape
        l, u = np.maximum(std.l, -INFTY), np.minimum(std.u, INFTY)
        wrapper = self._solvers.get(key)
        if wrapper is None:
            if len(self._solvers) >= MAX_CACHED:
                self._solvers.clear()
            wrapper = osqp.OSQP()
            wrapper.setup(triu_csc(std.P), std.q, dense_csc(std.C), l, u, **SETTINGS)
            self._solvers[key] = wrapper
            solver = wrapper._solver
        else:
            solver = wrapper._solver  # the compiled solver behind the Python wrapper
            rows, cols = triu_index(std.n)
            if solver.update_data_vec(std.q, l, u) or solver.update_data_mat(
                    std.P[rows, cols], None, std.C.ravel(order="F"), None):
                raise RuntimeError("OSQP rejected the data update")
        if warm_start is not None:
            solver.warm_start(np.asarray(warm_start, dtype=float).reshape(std.n), None)
        solver.solve()
        info = solver.info
        status = _STATUS.get(info.status_val, "failed")
        if status != "optimal":
            del self._solvers[key]  # its iterates would be a poor warm start for the next call
        return make_result(self.name, std, solver.solution.x, status, info.status)
