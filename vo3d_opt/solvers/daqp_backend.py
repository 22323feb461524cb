"""DAQP through its own Python API: a dual active-set solver for small dense QPs.

The :class:`~vo3d_opt.solvers.Standard` rows ``l <= C x <= u`` go to DAQP as they are: its last
n rows (the identity) as DAQP's simple bounds, the others as general rows, equalities marked
immutable. DAQP has no cones: the formulation substitutes a polygon for ``soc_radius``. On the
plane QPs (2 variables, about 30 rows) a solve takes a few microseconds, which makes it the
fastest backend here (benchmarks/bench_select.py); an active-set answer is exact to rounding.
"""

from __future__ import annotations

import functools

import daqp
import numpy as np

from vo3d_opt.solvers.base import Backend, Standard, make_result
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
def _order(n: int, m_ineq: int, m_eq: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows in DAQP's order and their ``sense`` flags, for one shape (read-only)."""
    m = m_ineq + m_eq
    rows = np.concatenate([np.arange(m, m + n), np.arange(m)])
    sense = np.zeros(n + m, dtype=np.int32)
    sense[n + m_ineq :] = EQUALITY
    rows.setflags(write=False)
    sense.setflags(write=False)
    return rows, sense
