"""``exact2d``: the exact solver of the per-plane problem, compiled
(``vo3d_opt/algorithm/exact2d.hpp``).

    minimise ||w - w0||²  over w in R²  subject to  ||w|| <= r_max,  G[k]·w <= h[k] (k < m),
    and, when r_min > 0, ||w|| >= r_min (an annulus).

The problem is LP-type: with the disc and the half-planes in a random order, the optimum of the
first k constraints either satisfies constraint k + 1 (and stays the optimum) or the new optimum
lies on constraint k + 1's line (the objective is strictly convex and the set convex), where it
is the projection of w0 onto the line clamped to the interval that the disc and the earlier
half-planes leave: a one-dimensional problem with an exact answer. This is Seidel's randomised
incremental algorithm, and the 2D steps of RVO2-3D's ``linearProgram1``/``linearProgram2``
(``src/Agent.cc``) with a nearest-point objective: expected O(m) time, an exact feasibility
verdict (up to a relative tolerance of ``EPS`` on touching constraints), no iterations.

The annulus v_min <= ||w|| is not convex. If the disc problem's optimum w* has ||w*|| >= r_min
it is also the annulus optimum (it is feasible, and the annulus set is a subset). Otherwise the
annulus optimum lies on the inner circle ||w|| = r_min: an optimum x with ||x|| > r_min would be
a local, hence global, minimum of the convex problem on the disc set, so x = w*, a contradiction.
On the circle the distance to w0 grows with the angle from w0's direction, and the allowed arcs
are cut out by the lines, so the answer is w0's direction on the circle if allowed, else the
allowed arc end (a line's crossing with the circle) nearest to it: O(m²), exact.
"""

from __future__ import annotations

import numpy as np

from vo3d_opt import _core
from vo3d_opt.solvers.base import Backend, Standard, make_result
from vo3d_opt.solvers.problem import QP, Result
from vo3d_opt.status import Status

#: Relative tolerance of the feasibility tests: a constraint met within EPS·(1 + |h| + r) holds.
EPS = 1e-12


def py_nearest_in_disc(
    G: np.ndarray,
    h: np.ndarray,
    m: int,
    w0: np.ndarray,
    r_max: float,
    r_min: float,
    order: np.ndarray,
    out: np.ndarray,
) -> bool:
    """The exact optimum of the module's problem over the first ``m`` rows of G w <= h, written
    into ``out`` (2,); False when the problem is infeasible. ``order``: scratch (>= m int64)
    that it fills with the rows' random order (Fisher–Yates with an xorshift: fixed, so that
    answers are reproducible to the last bit). ``r_max`` may be inf (no disc); ``r_min`` <= 0
    means no inner bound."""
    return bool(_core.nearest_in_disc(G, h, int(m), w0, float(r_max), float(r_min), order, out))


class Exact2DBackend(Backend):
    """``exact2d``: 2-variable QPs with an isotropic Hessian P = c·I (c > 0), inequalities,
    bounds and the speed disc as an exact cone; anything else is answered "failed"."""

    name = "exact2d"
    has_cones = True
    kind = "qp"
    checks_answers = True

    def _solve(self, qp: QP, std: Standard) -> Result:
        c = std.P[0, 0]
        if std.n != 2 or std.m_eq or not (c > 0 and std.P[0, 1] == 0 and std.P[1, 1] == c):
            return Result(
                None,
                Status.FAILED,
                self.name,
                "exact2d solves 2-variable QPs with P = c·I, c > 0, and no equalities",
            )
        _, _, D, d = std.split()
        w0 = -std.q / c
        out, order = np.empty(2), np.empty(max(len(d), 1), dtype=np.int64)
        r_max = np.inf if std.r is None else std.r
        if not py_nearest_in_disc(
            np.ascontiguousarray(D), np.ascontiguousarray(d), len(d), w0, r_max, 0.0, order, out
        ):
            return Result(None, Status.INFEASIBLE, self.name, "the constraints leave no point")
        return make_result(self.name, std, out, Status.OPTIMAL)
