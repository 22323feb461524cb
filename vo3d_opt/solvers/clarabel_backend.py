"""Clarabel through its own Python API, with the speed bound as an exact second-order cone.

Rows, as Clarabel's ``M x + s = b, s ∈ K``: the equalities (zero cone), then every finite bound
of the :class:`~vo3d_opt.solvers.Standard` rows as ``D x <= d`` (nonnegative cone), then
``s = [r; x]`` (second-order cone of size n + 1) when ``soc_radius`` is set. Every matrix entry
is stored, so problems with the same row counts share a pattern and a persistent solver is
updated in place rather than rebuilt (Clarabel is interior-point: there is no warm start).
"""

from __future__ import annotations

import functools

import clarabel
import numpy as np

from vo3d_opt.solvers._sparse import dense_csc, triu_csc, triu_index
from vo3d_opt.solvers.base import Backend, Standard, make_result
from vo3d_opt.solvers.problem import QP, Result
from vo3d_opt.status import Status

#: At most this many persistent solvers (one per structure); the cache is emptied when full.
MAX_CACHED = 64

_STATUS = {
    "Solved": Status.OPTIMAL,
    "AlmostSolved": Status.OPTIMAL,  # kept only if x is feasible
    "PrimalInfeasible": Status.INFEASIBLE,
    "AlmostPrimalInfeasible": Status.INFEASIBLE,
}


def conic_rows(std: Standard) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """(M, b, (zero-cone rows, nonnegative rows, SOC size)) for ``M x + s = b``."""
    if std.m_eq == 0 and float(std.l.max()) == -np.inf:
        # inequalities only, no lower bound (the formulations' problems): split's rows without
        # its masks and stacks
        finite = np.isfinite(std.u)
        E, e, D, d = _no_rows(std.n), _NONE, std.C[finite], std.u[finite]
    else:
        E, e, D, d = std.split()
    blocks, rhs, soc = [E, D], [e, d], 0
    if std.r is not None:
        soc = std.n + 1
        blocks.append(_soc_rows(std.n))
        rhs.append(np.concatenate([[std.r], np.zeros(std.n)]))
    return np.concatenate(blocks), np.concatenate(rhs), (E.shape[0], D.shape[0], soc)


_NONE = np.zeros(0)
_NONE.setflags(write=False)


@functools.cache
def _no_rows(n: int) -> np.ndarray:
    """(0, n), read-only."""
    rows = np.zeros((0, n))
    rows.setflags(write=False)
    return rows


@functools.cache
def _soc_rows(n: int) -> np.ndarray:
    """``s = [r; x]`` in the second-order cone: the rows [0; -I] of M (read-only)."""
    rows = np.vstack([np.zeros((1, n)), -np.eye(n)])
    rows.setflags(write=False)
    return rows


def settings() -> clarabel.DefaultSettings:
    """Quiet, tight settings that allow in-place data updates.

    With the cone active, x is only about as accurate as the square root of the gap tolerance
    (1e-5 with the default 1e-8), hence 1e-10.
    """
    s = clarabel.DefaultSettings()
    s.verbose = False
    s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = 1e-10
    s.presolve_enable = False
    s.input_sparse_dropzeros = False
    return s


class ClarabelBackend(Backend):
    """Clarabel interior-point conic solver; takes ``soc_radius`` as an exact cone."""

    name = "clarabel"
    has_cones = True
    kind = "qp"
    checks_answers = True

    def __init__(self) -> None:
        self._solvers: dict[tuple[int, int, int, int], clarabel.DefaultSolver] = {}

    def _solve(self, qp: QP, std: Standard) -> Result:
        M, b, sizes = conic_rows(std)
        key = (std.n, *sizes)
        solver = self._solvers.get(key)
        if solver is None:
            if len(self._solvers) >= MAX_CACHED:
                self._solvers.clear()
            cones = [
                cone(size)
                for cone, size in zip(
                    (clarabel.ZeroConeT, clarabel.NonnegativeConeT, clarabel.SecondOrderConeT),
                    sizes,
                    strict=True,
                )
                if size
            ]
            solver = clarabel.DefaultSolver(
                triu_csc(std.P), std.q, dense_csc(M), b, cones, settings()
            )
            self._solvers[key] = solver
        # Always through update(), also right after set-up: a fresh solver and an updated
        # one differ in the last digits, and a run must not depend on what came before.
        rows, cols = triu_index(std.n)
        solver.update(P=std.P[rows, cols], q=std.q, A=M.ravel(order="F"), b=b)
        sol = solver.solve()
        status = str(sol.status)
        return make_result(self.name, std, sol.x, _STATUS.get(status, Status.FAILED), status)
