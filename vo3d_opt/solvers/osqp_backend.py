"""OSQP through its own Python API, with one persistent solver per problem shape.

OSQP takes the :class:`~vo3d_opt.solvers.Standard` rows ``l <= C x <= u`` as they are. Every
entry of C and of P's upper triangle is stored (dense pattern), so problems of the same shape
share a sparsity pattern: the solver set up for the first is updated in place and warm-started
from its last answer for the next (OSQP's ``update`` and ``solve``: see ``_update``).

OSQP 1.x prints "Polishing not needed" whatever ``verbose`` says when the optimum has no active
constraint (osqp/osqp#785). Such problems are answered before OSQP runs: when P is positive
definite and the unconstrained minimiser -P⁻¹q satisfies every constraint, it is the optimum.

The standard form costs more in Python than the update of a warm solver: a QP of the
formulations' usual kind (``G x <= h`` alone, float arrays, finite, P symmetric: one compiled
check, as for DAQP) goes to OSQP as its rows alone, and its answer is checked against
``G x <= h`` in one compiled call; anything else, and any answer that check does not pass at
once, takes the standard form.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import osqp

from vo3d_opt import _core
from vo3d_opt.solvers._sparse import dense_csc, triu_csc, triu_index
from vo3d_opt.solvers.base import (
    FEAS_TOL,
    Backend,
    Standard,
    failure,
    make_result,
    plain_rows,
    standardise,
)
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


def minimiser(P: np.ndarray, q: np.ndarray) -> np.ndarray | None:
    """-P⁻¹q when P (symmetric) is positive definite and the answer finite, else None; in
    closed form for two variables (the plane QPs), where numpy's solve and Cholesky would cost
    more than OSQP's update."""
    if q.shape[0] != 2:
        try:
            np.linalg.cholesky(P)  # raises unless positive definite
            x = np.linalg.solve(P, -q)
        except np.linalg.LinAlgError:
            return None
    else:
        (a, b), (_, d) = P.tolist()
        q0, q1 = q.tolist()
        det = a * d - b * b
        if not (a > 0.0 and det > 0.0):
            return None
        x = np.array([(b * q1 - d * q0) / det, (b * q0 - a * q1) / det])
    return x if np.isfinite(x).all() else None


def unconstrained_optimum(std: Standard) -> np.ndarray | None:
    """-P⁻¹q when it satisfies every constraint and P is positive definite, else None."""
    x = minimiser(std.P, std.q)
    return None if x is None or std.violation(x) > 0.0 else x


class OsqpBackend(Backend):
    """OSQP with a polished, tightly converged answer; polygons only (no cones)."""

    name = "osqp"
    has_cones = False
    kind = "qp"
    checks_answers = True

    def __init__(self) -> None:
        self._solvers: dict[tuple[str, int, int], osqp.OSQP] = {}

    def solve(self, qp: QP) -> Result:
        """OSQP on the rows alone when the QP is ``G x <= h`` alone (the module's docstring),
        else on the standard form (:meth:`Backend.solve`)."""
        if (rows := plain_rows(qp)) is None:
            return super().solve(qp)
        P, q, G, h = rows
        try:
            x = minimiser(P, q)
            if x is not None and _core.qp_rows_gap(G, h, x) <= 0.0:
                return Result(x, Status.OPTIMAL, self.name, "unconstrained optimum is feasible")
            u = np.minimum(h, INFTY)  # as OSQP would clip it
            x, status, info = self._run("rows", P, q, G, _lowest(h.shape[0]), u)
        except Exception as exc:  # noqa: BLE001 - a backend never raises on a well-formed QP
            return failure(self.name, exc)
        if status == Status.OPTIMAL and _core.qp_rows_gap(G, h, x) <= FEAS_TOL:
            return Result(np.array(x), Status.OPTIMAL, self.name, info)  # ours, not OSQP's
        return make_result(self.name, standardise(qp), x, status, info)

    def _solve(self, qp: QP, std: Standard) -> Result:
        if (x := unconstrained_optimum(std)) is not None:
            return Result(x, Status.OPTIMAL, self.name, "unconstrained optimum is feasible")
        l, u = np.maximum(std.l, -INFTY), np.minimum(std.u, INFTY)  # noqa: E741 - as in Standard
        x, status, info = self._run("standard", std.P, std.q, std.C, l, u)
        return make_result(self.name, std, x, status, info)

    def _run(
        self,
        form: str,
        P: np.ndarray,
        q: np.ndarray,
        C: np.ndarray,
        l: np.ndarray,  # noqa: E741 - l <= C x <= u, as in Standard
        u: np.ndarray,
    ) -> tuple[np.ndarray | None, Status, str]:
        """OSQP on ``l <= C x <= u``: the persistent solver of this form and shape updated and
        warm-started (set up for the first), its answer (OSQP's own array), status and word."""
        key = (form, *C.shape)
        solver = self._solvers.get(key)
        if solver is None:
            if len(self._solvers) >= MAX_CACHED:
                self._solvers.clear()
            solver = osqp.OSQP()
            solver.setup(triu_csc(P), q, dense_csc(C), l, u, **SETTINGS)
            self._solvers[key] = solver
        else:
            rows, cols = triu_index(q.shape[0])
            _update(solver, q, l, u, P[rows, cols], C.ravel(order="F"))
        x, info = _solve(solver)
        status = _STATUS.get(info.status_val, Status.FAILED)
        if status != Status.OPTIMAL:
            del self._solvers[key]  # its iterates would be a poor warm start for the next call
        return x, status, info.status


# OSQP's Python wrapper (osqp.OSQP) costs a plane QP's update and solve about 13 µs of the
# solver's 80 besides its compiled solver (it clips the bounds again, keeps data for
# derivatives, copies every field of the answer's info): where that compiled solver is there
# (osqp 1.x: OSQP._solver) the same two calls go to it directly, with the same answers.


def _update(
    solver: osqp.OSQP,
    q: np.ndarray,
    l: np.ndarray,  # noqa: E741 - as in Standard, within ±INFTY
    u: np.ndarray,
    Px: np.ndarray,
    Ax: np.ndarray,
) -> None:
    """``solver.update(q=q, l=l, u=u, Px=Px, Ax=Ax)`` (the bounds already within ±INFTY)."""
    raw = getattr(solver, "_solver", None)
    if raw is None or not hasattr(raw, "update_data_vec"):
        solver.update(q=q, l=l, u=u, Px=Px, Ax=Ax)
        return
    raw.update_data_vec(q=q, l=l, u=u)
    raw.update_data_mat(P_x=Px, P_i=None, A_x=Ax, A_i=None)


def _solve(solver: osqp.OSQP) -> tuple[np.ndarray, Any]:
    """``solver.solve()``'s answer and info."""
    raw = getattr(solver, "_solver", None)
    if raw is None or not hasattr(raw, "solution"):
        res = solver.solve(raise_error=False)
        return res.x, res.info
    raw.solve()
    return raw.solution.x, raw.info


@functools.lru_cache(maxsize=256)
def _lowest(m: int) -> np.ndarray:
    """m times OSQP's minus infinity: the lower bounds of m rows ``G x <= h`` (read-only)."""
    lower = np.full(m, -INFTY)
    lower.setflags(write=False)
    return lower
