"""cvxpy, with a parameterised (DPP) problem cached per shape so it is compiled once.

The objective is written ``½‖F x‖² + qᵀx`` with ``FᵀF = P`` (F from an eigendecomposition), the
constraints ``D x <= d`` (every finite bound of the :class:`~vo3d_opt.solvers.Standard` rows),
``E x = e`` and, when ``soc_radius`` is set, ``‖x‖ <= r`` (an exact cone; needs a conic solver).
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from vo3d_opt.solvers.base import Backend, Standard, make_result
from vo3d_opt.solvers.certify import certified_infeasible
from vo3d_opt.solvers.problem import QP, Result
from vo3d_opt.status import Status

#: Extra options per cvxpy solver, for answers as tight as the direct backends'. OSQP is left
#: unpolished: OSQP 1.x prints a line per polished solve without an active set.
SOLVER_OPTIONS: dict[str, dict[str, float | int | bool | str]] = {
    "OSQP": dict(eps_abs=1e-8, eps_rel=1e-8, polishing=False, max_iter=20_000),
    "SCS": dict(eps_abs=1e-9, eps_rel=1e-9, max_iters=20_000),
    "CLARABEL": dict(tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10),
    # CVXOPT's defaults (abstol 1e-7, reltol 1e-6, feastol 1e-7) stop up to ~1e-4 away. At
    # 1e-9 its default KKT solver (Cholesky) ends some QPs in a solver error, and which ones
    # changes with the machine and the BLAS (one of the tests' QPs with 3 refinement steps on
    # an AMD EPYC with cvxpy 1.9.3 / cvxopt 1.3.3, none with 2 or 4): cvxpy's LDL-based
    # "robust" KKT solver solves them all
    "CVXOPT": dict(abstol=1e-9, reltol=1e-9, feastol=1e-8, refinement=3, kktsolver="robust"),
}

#: Solvers whose "infeasible" is not trustworthy here (ProxQP calls some narrow feasible QPs
#: infeasible): kept only when Clarabel agrees, else reported as "failed".
UNRELIABLE_INFEASIBILITY = {"PROXQP"}

_STATUS = {
    cp.OPTIMAL: Status.OPTIMAL,
    cp.OPTIMAL_INACCURATE: Status.OPTIMAL,  # kept only if x is feasible
    cp.INFEASIBLE: Status.INFEASIBLE,
    cp.INFEASIBLE_INACCURATE: Status.INFEASIBLE,
}


@dataclass
class _Template:
    """A problem and its parameters for one shape; None for the parts the shape lacks."""

    problem: cp.Problem
    x: cp.Variable
    F: cp.Parameter
    q: cp.Parameter
    D: cp.Parameter | None
    d: cp.Parameter | None
    E: cp.Parameter | None
    e: cp.Parameter | None
    r: cp.Parameter | None


def _template(n: int, m_ineq: int, m_eq: int, soc: bool) -> _Template:
    x = cp.Variable(n)
    F, q = cp.Parameter((n, n)), cp.Parameter(n)
    D = cp.Parameter((m_ineq, n)) if m_ineq else None
    d = cp.Parameter(m_ineq) if m_ineq else None
    E = cp.Parameter((m_eq, n)) if m_eq else None
    e = cp.Parameter(m_eq) if m_eq else None
    r = cp.Parameter(nonneg=True) if soc else None
    constraints = []
    if D is not None:
        constraints.append(D @ x <= d)
    if E is not None:
        constraints.append(E @ x == e)
    if r is not None:
        constraints.append(cp.norm(x, 2) <= r)
    problem = cp.Problem(cp.Minimize(0.5 * cp.sum_squares(F @ x) + q @ x), constraints)
    return _Template(problem, x, F, q, D, d, E, e, r)


def square_root(P: np.ndarray) -> np.ndarray:
    """F with FᵀF = P for a symmetric positive semidefinite P (negative eigenvalues clipped)."""
    w, V = np.linalg.eigh(P)
    return np.sqrt(np.clip(w, 0.0, None))[:, None] * V.T


class CvxpyBackend(Backend):
    """cvxpy with a fixed solver (``cvxpy:<SOLVER>``) or cvxpy's own choice (``cvxpy``)."""

    kind = "qp"
    checks_answers = True

    def __init__(self, name: str, solver: str | None, has_cones: bool) -> None:
        self.name = name
        self.has_cones = has_cones
        self._solver = solver
        self._options = SOLVER_OPTIONS.get(solver or "", {})
        self._templates: dict[tuple[int, int, int, bool], _Template] = {}

    def _solve(self, qp: QP, std: Standard) -> Result:
        E, e, D, d = std.split()
        key = (std.n, D.shape[0], E.shape[0], std.r is not None)
        if key not in self._templates:
            self._templates[key] = _template(*key)
        t = self._templates[key]
        t.F.value, t.q.value = square_root(std.P), std.q
        if t.D is not None and t.d is not None:  # both or neither, by the shape
            t.D.value, t.d.value = D, d
        if t.E is not None and t.e is not None:
            t.E.value, t.e.value = E, e
        if t.r is not None:
            t.r.value = std.r
        # No warm start from the last problem of this shape (cvxpy's default): an answer must not
        # depend on the calls before it.
        t.problem.solve(solver=self._solver, warm_start=False, **self._options)
        native = t.problem.status
        status = _STATUS.get(native, Status.FAILED)
        if (
            status == Status.INFEASIBLE
            and self._solver in UNRELIABLE_INFEASIBILITY
            and not certified_infeasible(qp)
        ):
            status, native = Status.FAILED, f"{native}, but Clarabel finds the QP feasible"
        return make_result(self.name, std, t.x.value, status, native)
