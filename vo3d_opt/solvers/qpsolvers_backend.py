"""Any solver of qpsolvers (``qpsolvers:<name>``), through ``qpsolvers.solve_problem``.

The problem is passed without infinities, as ``G x <= h`` (every finite bound of the
:class:`~vo3d_opt.solvers.Standard` rows, box bounds included) and ``A x = b``, in CSC form for
the solvers that want sparse matrices. qpsolvers reports only whether a solution was found:
when none is, the problem is "infeasible" if Clarabel proves it so, else "failed". No cones: the
formulation substitutes a polygon for ``soc_radius``.
"""

from __future__ import annotations

from typing import Any

import qpsolvers
import scipy.sparse as sp

from vo3d_opt.solvers.base import Backend, Standard, make_result
from vo3d_opt.solvers.certify import certified_infeasible
from vo3d_opt.solvers.problem import QP, Result
from vo3d_opt.status import Status

#: Extra options per solver, for answers as tight as the direct backends'. OSQP is left
#: unpolished: OSQP 1.x prints a line per polished solve without an active set. ProxQP stays
#: unreliable here whatever its settings (it calls some narrow feasible QPs infeasible).
SOLVER_OPTIONS: dict[str, dict[str, float | int | bool]] = {
    "osqp": dict(eps_abs=1e-8, eps_rel=1e-8, polishing=False, max_iter=20_000),
    "scs": dict(eps_abs=1e-9, eps_rel=1e-9, max_iters=20_000),
    "proxqp": dict(eps_abs=1e-9),
    # CVXOPT's defaults (abstol 1e-7, reltol 1e-6, feastol 1e-7) stop up to ~1e-4 away
    "cvxopt": dict(abstol=1e-9, reltol=1e-9, feastol=1e-9),
}


def to_problem(std: Standard, sparse: bool) -> qpsolvers.Problem:
    """The qpsolvers Problem for ``std``; CSC matrices when ``sparse``."""
    E, e, D, d = std.split()
    P = sp.csc_matrix(std.P) if sparse else std.P
    G = (sp.csc_matrix(D) if sparse else D) if d.size else None
    A = (sp.csc_matrix(E) if sparse else E) if e.size else None
    return qpsolvers.Problem(P, std.q, G, d if d.size else None, A, e if e.size else None)


class QpsolversBackend(Backend):
    """One qpsolvers solver; polygons only (no cones)."""

    has_cones = False
    kind = "qp"
    checks_answers = True

    def __init__(self, name: str, solver: str) -> None:
        self.name = name
        self._solver = solver
        self._options: dict[str, Any] = SOLVER_OPTIONS.get(solver, {})  # solver-specific **kwargs
        self._sparse = solver not in qpsolvers.dense_solvers

    def _solve(self, qp: QP, std: Standard) -> Result:
        sol = qpsolvers.solve_problem(
            to_problem(std, self._sparse), solver=self._solver, **self._options
        )
        if sol.found:
            return make_result(self.name, std, sol.x, Status.OPTIMAL)
        if certified_infeasible(qp):
            return Result(
                None, Status.INFEASIBLE, self.name, "no solution; Clarabel proves infeasible"
            )
        return Result(
            None, Status.FAILED, self.name, "no solution found, yet QP not proved infeasible"
        )
