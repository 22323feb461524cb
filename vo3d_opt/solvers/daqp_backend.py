"""DAQP through its own Python API: a dual active-set solver for small dense QPs.

The :class:`~vo3d_opt.solvers.Standard` rows ``l <= C x <= u`` go to DAQP as they are: its last
n rows (the identity) as DAQP's simple bounds, the others as general rows, equalities marked
immutable. DAQP has no cones: the formulation substitutes a polygon for ``soc_radius``. On the
plane QPs (2 variables, about 30 rows) a solve takes a few microseconds, which makes it the
fastest backend here (benchmarks/bench_select.py); an active-set answer is exact to rounding.

A solve of a few microseconds is less than the standard form costs in Python, so a QP of the
formulations' usual kind (``G x <= h`` alone, float arrays, finite, P symmetric: one compiled
check) goes to DAQP as it is, its rows as DAQP's general rows with no simple bounds, and its
answer is checked against ``G x <= h`` in one compiled call; anything else, and any answer that
check does not pass at once, takes the standard form.
"""

from __future__ import annotations

import functools

import daqp
import numpy as np

from vo3d_opt import _core
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

#: DAQP's infinity: bounds beyond it are clipped to it.
INF = 1e30
#: ``sense`` flag of an equality (active and immutable).
EQUALITY = 5
_STATUS = {1: Status.OPTIMAL, 2: Status.OPTIMAL, -1: Status.INFEASIBLE}
_CODES = {
    1: "optimal",
    2: "soft optimal",
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "iteration limit",
    -5: "nonconvex",
    -6: "overdetermined initial active set",
}


class DaqpBackend(Backend):
    """DAQP dual active-set solver; polygons only (no cones)."""

    name = "daqp"
    has_cones = False
    kind = "qp"
    checks_answers = True

    def solve(self, qp: QP) -> Result:
        """DAQP on the rows as they are when the QP is ``G x <= h`` alone (the module's
        docstring), else on the standard form (:meth:`Backend.solve`)."""
        if (rows := plain_rows(qp)) is None:
            return super().solve(qp)
        P, q, G, h = rows
        lower, sense = _open_rows(h.shape[0])
        try:
            x, _, flag, _ = daqp.solve(P, q, G, h, lower, sense)
        except Exception as exc:  # noqa: BLE001 - a backend never raises on a well-formed QP
            return failure(self.name, exc)
        if flag == -1:
            return Result(None, Status.INFEASIBLE, self.name, _CODES[-1])
        if flag in (1, 2) and _core.qp_rows_gap(G, h, x) <= FEAS_TOL:
            return Result(x, Status.OPTIMAL, self.name, _CODES[flag])
        status = _STATUS.get(flag, Status.FAILED)
        return make_result(self.name, standardise(qp), x, status, _CODES.get(flag, str(flag)))

    def _solve(self, qp: QP, std: Standard) -> Result:
        upper, lower, sense = _daqp_rows(std.l, std.u, std.n, std.m_ineq, std.m_eq)
        x, _, flag, _ = daqp.solve(
            std.P, std.q, std.C[: std.m_ineq + std.m_eq], upper, lower, sense
        )
        return make_result(
            self.name, std, x, _STATUS.get(flag, Status.FAILED), _CODES.get(flag, str(flag))
        )


def _daqp_rows(
    l: np.ndarray,  # noqa: E741 - l as in Standard
    u: np.ndarray,
    n: int,
    m_ineq: int,
    m_eq: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """DAQP's bounds: the simple bounds (the identity rows, last in Standard) first, clipped to
    its infinity, and the ``sense`` flags marking equalities immutable."""
    rows, sense = _order(n, m_ineq, m_eq)
    upper, lower = np.minimum(u[rows], INF), np.maximum(l[rows], -INF)
    return upper, lower, sense.copy()


@functools.lru_cache(maxsize=256)
def _open_rows(m: int) -> tuple[np.ndarray, np.ndarray]:
    """DAQP's lower bounds (its minus infinity) and ``sense`` flags (inequalities) of m general
    rows with no simple bounds, for the short path. Shared, so writable only because DAQP's
    Python API takes no read-only buffer; DAQP reads them and never writes."""
    return np.full(m, -INF), np.zeros(m, dtype=np.int32)


@functools.lru_cache(maxsize=256)
def _order(n: int, m_ineq: int, m_eq: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows in DAQP's order and their ``sense`` flags, for one shape (read-only)."""
    m = m_ineq + m_eq
    rows = np.concatenate([np.arange(m, m + n), np.arange(m)])
    sense = np.zeros(n + m, dtype=np.int32)
    sense[n + m_ineq :] = EQUALITY
    rows.setflags(write=False)
    sense.setflags(write=False)
    return rows, sense
