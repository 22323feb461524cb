"""The interface every backend implements, and the checks they share.

A backend's ``solve(qp)`` standardises and screens the problem once (:class:`Standard`,
:func:`screen`), then calls its own ``_solve``; :func:`make_result` turns a solver's raw answer
into a :class:`Result` that is "optimal" only when x is finite and satisfies every constraint
within :data:`FEAS_TOL`. A backend never raises on a well-formed problem.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import numpy as np

from vo3d_opt import _core
from vo3d_opt.solvers.problem import NLP, QP, Result
from vo3d_opt.status import Status

#: Largest constraint violation, relative to 1 + the largest finite right-hand side, that an
#: "optimal" answer may have.
FEAS_TOL = 1e-6


class Backend:
    """One solver behind the common interface; subclasses set the three attributes."""

    name: str
    #: True when ``QP.soc_radius`` is taken as an exact second-order cone.
    has_cones: bool
    kind: Literal["qp", "nlp"]
    #: True for the backends of this package, whose "optimal" answers are already checked
    #: against every constraint (``make_result``); others are checked by the selector.
    checks_answers: bool = False

    def solve(self, qp: QP) -> Result:
        """Solve a QP: the checks every QP backend shares, then its own ``_solve``. Never
        raises on a well-formed QP (a ValueError for a cone given to a backend without cones)."""
        if not self.has_cones:
            require_no_cone(self, qp)
        std = standardise(qp)
        if (early := screen(std, self.name)) is not None:
            return early
        try:
            return self._solve(qp, std)
        except Exception as exc:  # noqa: BLE001 - a backend never raises on a well-formed QP
            return failure(self.name, exc)

    def _solve(self, qp: QP, std: Standard) -> Result:
        """The backend's own solve of a screened QP (QP backends override it)."""
        raise NotImplementedError(f"backend {self.name!r} does not solve QPs")

    def solve_nlp(self, nlp: NLP) -> Result:
        """Solve an NLP with exact cone constraints (nlp backends)."""
        raise NotImplementedError(f"backend {self.name!r} does not solve NLPs")

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


# ----------------------------------------------------------------------------------------------
# helpers shared by the backend modules


@dataclass(slots=True)
class Standard:
    """A QP as  min ½xᵀPx + qᵀx  s.t.  l <= C x <= u,  ||x|| <= r (when r is not None).

    The rows of C are G's (l = -inf, u = h), then A's (l = u = b), then the n rows of the
    identity (l = lb, u = ub, infinite where absent). P is symmetric; arrays are float.
    """

    P: np.ndarray
    q: np.ndarray
    C: np.ndarray
    l: np.ndarray  # noqa: E741 - l <= C x <= u, OSQP's standard form
    u: np.ndarray
    r: float | None
    m_ineq: int
    m_eq: int

    @property
    def n(self) -> int:
        return self.q.shape[0]

    def split(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(E, e, D, d): the equalities E x = e, and every finite bound as a row of D x <= d
        (upper bounds first, then lower bounds negated)."""
        eq = slice(self.m_ineq, self.m_ineq + self.m_eq)
        ineq = np.ones(self.C.shape[0], dtype=bool)
        ineq[eq] = False
        upper, lower = ineq & np.isfinite(self.u), ineq & np.isfinite(self.l)
        return (
            self.C[eq],
            self.u[eq],
            np.vstack([self.C[upper], -self.C[lower]]),
            np.concatenate([self.u[upper], -self.l[lower]]),
        )

    def violation(self, x: np.ndarray) -> float:
        """Largest constraint violation of x, relative to 1 + the largest finite bound.

        Violations up to :data:`FEAS_TOL` are returned unscaled (an upper bound), to save time.
        """
        return _violation(
            self.C, self.l, self.u, np.asarray(x, dtype=float), -1.0 if self.r is None else self.r
        )


def _violation(C: np.ndarray, l: np.ndarray, u: np.ndarray, x: np.ndarray, r: float) -> float:  # noqa: E741
    """``Standard.violation`` (r < 0: no radius): each row's C x summed column by column, as
    the rows are written; the radius's |x| as numpy sums it (compiled: ``_core.qp_violation``,
    for up to 8 variables with a radius; a NaN gap never wins)."""
    if r < 0.0 or x.shape[0] <= 8:
        worst = float(_core.qp_violation(C, l, u, x, r))
    else:
        worst = max(float(_core.qp_violation(C, l, u, x, -1.0)), float(np.sqrt(np.sum(x * x))) - r)
    if worst <= FEAS_TOL:  # the scale only matters for larger violations
        return worst
    bounds = np.abs(np.concatenate([l, u]))
    scale = max(0.0 if r < 0.0 else r, float(bounds[np.isfinite(bounds)].max(initial=0.0)))
    return worst / (1.0 + scale)


@functools.cache
def _infinite(n: int) -> np.ndarray:
    """n times +inf, shared (read-only)."""
    inf = np.full(n, np.inf)
    inf.setflags(write=False)
    return inf


@functools.cache
def _eye(n: int) -> np.ndarray:
    """The n×n identity, shared (read-only)."""
    eye = np.eye(n)
    eye.setflags(write=False)
    return eye


def _matrix(value: np.ndarray | None, cols: int, field: str) -> np.ndarray:
    if value is None:
        return _eye(cols)[:0]
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1 and arr.size == cols:
        arr = arr.reshape(1, cols)
    if arr.ndim != 2 or arr.shape[1] != cols:
        raise ValueError(f"QP.{field} must have shape (m, {cols}), got {np.shape(value)}")
    return arr


def _vector(value: np.ndarray | None, size: int, fill: float, field: str) -> np.ndarray:
    if value is None:
        return np.full(size, fill)
    arr = np.asarray(value, dtype=float)
    if arr.shape != (size,):
        if arr.size != size:
            raise ValueError(f"QP.{field} must have shape ({size},), got {np.shape(value)}")
        arr = arr.reshape(size)
    return arr


def standardise(qp: QP) -> Standard:
    """``qp`` in :class:`Standard` form; ValueError when its shapes do not fit together.

    Non-finite numbers are kept: see :func:`screen`.
    """
    q = np.array(qp.q, dtype=float).reshape(-1)  # a copy: solvers may want writable buffers
    n = q.shape[0]
    if n == 0:
        raise ValueError("QP.q must have at least one entry")
    P = np.asarray(qp.P, dtype=float)
    if P.shape != (n, n):
        raise ValueError(f"QP.P must have shape ({n}, {n}), got {P.shape}")
    if (qp.G is None) != (qp.h is None) or (qp.A is None) != (qp.b is None):
        raise ValueError("QP.G and QP.h (and QP.A and QP.b) must be given together")
    r = None if qp.soc_radius is None else float(qp.soc_radius)
    if (
        qp.A is None
        and qp.lb is None
        and qp.ub is None
        and isinstance(qp.G, np.ndarray)
        and qp.G.dtype == float
        and qp.G.ndim == 2
        and qp.G.shape[1] == n
        and isinstance(qp.h, np.ndarray)
        and qp.h.dtype == float
        and qp.h.shape == (qp.G.shape[0],)
    ):
        # The formulations' usual problem (inequalities only, float arrays): _rows' arrays
        # without conversions.
        m = qp.G.shape[0]
        C, u = np.concatenate((qp.G, _eye(n))), np.concatenate((qp.h, _infinite(n)))
        l = np.full(m + n, -np.inf)  # noqa: E741
        return Standard(P=0.5 * (P + P.T), q=q, C=C, l=l, u=u, r=r, m_ineq=m, m_eq=0)
    G, A = _matrix(qp.G, n, "G"), _matrix(qp.A, n, "A")
    h = _vector(qp.h, G.shape[0], np.inf, "h")
    b = _vector(qp.b, A.shape[0], 0.0, "b")
    lb, ub = _vector(qp.lb, n, -np.inf, "lb"), _vector(qp.ub, n, np.inf, "ub")
    C, l, u = _rows(G, h, A, b, lb, ub)  # noqa: E741 - l as in Standard
    return Standard(P=0.5 * (P + P.T), q=q, C=C, l=l, u=u, r=r, m_ineq=G.shape[0], m_eq=A.shape[0])


def _rows(
    G: np.ndarray, h: np.ndarray, A: np.ndarray, b: np.ndarray, lb: np.ndarray, ub: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """C = [G; A; I], l = [-inf; b; lb], u = [h; b; ub]."""
    n = lb.shape[0]
    C = np.vstack([G, A, _eye(n)])
    l = np.concatenate([np.full(G.shape[0], -np.inf), b, lb])  # noqa: E741
    u = np.concatenate([h, b, ub])
    return C, l, u


def screen(std: Standard, solver: str) -> Result | None:
    """The Result for data no solver should see (NaN, misplaced infinities), else None.

    Infinities are allowed only where they drop a constraint (h = +inf, lb = -inf, ub = +inf).
    Lower bounds above upper bounds, h = -inf and a negative radius are infeasible.
    """
    code = _screen(
        std.P,
        std.q,
        std.C,
        std.l,
        std.u,
        np.nan if std.r is None else std.r,
        std.r is not None,
        std.m_ineq,
        std.m_eq,
    )
    if code == 0:
        return None
    if code == 1:
        return Result(
            None, Status.FAILED, solver, "problem data contains NaN or a misplaced infinity"
        )
    if code == 2:
        return Result(None, Status.FAILED, solver, "b contains an infinity")
    return Result(
        None, Status.INFEASIBLE, solver, "a bound or a negative radius excludes every point"
    )


def _screen(
    P: np.ndarray,
    q: np.ndarray,
    C: np.ndarray,
    l: np.ndarray,  # noqa: E741 - l as in Standard
    u: np.ndarray,
    r: float,
    has_r: bool,
    m_ineq: int,
    m_eq: int,
) -> int:
    """0: fine; 1: NaN or a misplaced infinity (or data so large that its sum overflows); 2: an
    infinite b; 3: infeasible bounds (compiled: ``_core.qp_screen``, one pass where numpy
    would take a dozen reductions)."""
    return int(_core.qp_screen(P, q, C, l, u, r, has_r, m_ineq, m_eq))


def plain_rows(qp: QP) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """P, q, G, h of ``qp`` when it is rows ``G x <= h`` alone that a solver can take as they
    are (float arrays, finite, P symmetric: ``_core.qp_rows_form``; writable copies of
    read-only ones), for the short paths of DAQP and OSQP; None: the standard form decides."""
    plain = qp.A is None and qp.b is None and qp.lb is None and qp.ub is None
    if not plain or qp.soc_radius is not None or qp.G is None or qp.h is None:
        return None
    form = _core.qp_rows_form(qp.P, qp.q, qp.G, qp.h)
    if form == 1:
        return None
    P, q, G, h = qp.P, qp.q, qp.G, qp.h
    if form == 2:  # DAQP's Python API takes no read-only buffer
        return np.array(P), np.array(q), np.array(G), np.array(h)
    return P, q, G, h


def require_no_cone(backend: Backend, qp: QP) -> None:
    """Raise ValueError when a backend without cones is given a QP with ``soc_radius``."""
    if qp.soc_radius is not None:
        raise ValueError(
            f"solver {backend.name!r} has no second-order cones: replace QP.soc_radius with a "
            "polygon first (see Backend.has_cones)"
        )


def failure(solver: str, exc: BaseException) -> Result:
    """The Result for an exception raised inside a solver."""
    return Result(None, Status.FAILED, solver, f"{type(exc).__name__}: {exc}")


def make_result(
    solver: str, std: Standard, x: np.ndarray | None, status: Status, info: str = ""
) -> Result:
    """A Result whose x is None or a finite array of shape (n,).

    An "optimal" claim is downgraded to "failed" when x is missing, not finite, or violates a
    constraint by more than :data:`FEAS_TOL`; an "infeasible" answer carries no x.
    """
    arr = None
    if x is not None and status != Status.INFEASIBLE:
        arr = np.array(x, dtype=float).reshape(-1)
        if arr.shape != (std.n,) or not np.isfinite(arr).all():
            arr = None
    if status == Status.OPTIMAL:
        if arr is None:
            status, info = Status.FAILED, info or "solver returned no finite solution"
        elif not (v := std.violation(arr)) <= FEAS_TOL:
            status, info = Status.FAILED, f"solution violates the constraints by {v:.2e} (relative)"
    return Result(arr, status, solver, info)
