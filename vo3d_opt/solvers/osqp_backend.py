"""OSQP through its own Python API, with one persistent solver per problem shape.

OSQP takes the :class:`~vo3d_opt.solvers.Standard` rows ``l <= C x <= u`` as they are. Every
entry of C and of P's upper triangle is stored (dense pattern), so problems of the same shape
share a sparsity pattern: the solver set up for the first is updated in place and warm-started
from its last answer for the next, through OSQP's public ``update`` and ``solve``.

OSQP 1.x prints "Polishing not needed" whatever ``verbose`` says when the optimum has no active
constraint (osqp/osqp#785). Such problems are answered before OSQP runs: when P is positive
definite and the unconstrained minimiser -P⁻¹q satisfies every constraint, it is the optimum.
"""

from __future__ import annotations

import numpy as np
import osqp

from vo3d_opt.solvers._sparse import dense_csc, triu_csc, triu_index
from vo3d_opt.solvers.base import Backend, Standard, make_result
from vo3d_opt.solvers.problem import QP, Result
from vo3d_opt.status import Status

#: Settings of every solver: tight tolerances, polishing, silence.
SETTINGS = dict(eps_abs=1e-7, eps_rel=1e-7, polishing=True, verbose=False, max_iter=10_000)
#: At most this many persistent solvers (one per shape); the cache is emptied when full.
MAX_CACHED = 64
#: OSQP's infinity: bounds beyond it are clipped to it.
INFTY = osqp.constant("OSQP_INFTY")

_STATUS = {
    osqp.SolverStatus.OSQP_SOLVED: Status.OPTIMAL,
    osqp.SolverStatus.OSQP_SOLVED_INACCURATE: Status.OPTIMAL,  # kept only if x is feasible
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE: Status.INFEASIBLE,
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE: Status.INFEASIBLE,
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

    def _solve(self, qp: QP, std: Standard) -> Result:
        if (x := unconstrained_optimum(std)) is not None:
            return Result(x, Status.OPTIMAL, self.name, "unconstrained optimum is feasible")
        key = std.C.shape
        l, u = np.maximum(std.l, -INFTY), np.minimum(std.u, INFTY)  # noqa: E741 - as in Standard
        solver = self._solvers.get(key)
        if solver is None:
            if len(self._solvers) >= MAX_CACHED:
                self._solvers.clear()
            solver = osqp.OSQP()
            solver.setup(triu_csc(std.P), std.q, dense_csc(std.C), l, u, **SETTINGS)
            self._solvers[key] = solver
        else:
            rows, cols = triu_index(std.n)
            solver.update(q=std.q, l=l, u=u, Px=std.P[rows, cols], Ax=std.C.ravel(order="F"))
        res = solver.solve(raise_error=False)
        status = _STATUS.get(res.info.status_val, Status.FAILED)
        if status != Status.OPTIMAL:
            del self._solvers[key]  # its iterates would be a poor warm start for the next call
        return make_result(self.name, std, res.x, status, res.info.status)
