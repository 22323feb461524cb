"""``exact2d``: the exact solver of the per-plane problem, compiled.

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

from vo3d_opt._jit import entry, inline, kernel
from vo3d_opt.solvers.base import Backend, Standard, make_result
from vo3d_opt.solvers.problem import QP, Result
from vo3d_opt.status import Status

#: Relative tolerance of the feasibility tests: a constraint met within EPS·(1 + |h| + r) holds.
EPS = 1e-12


@inline
def seidel_order(m: int, out: np.ndarray) -> None:
    """A fixed pseudo-random permutation of range(m) (Fisher–Yates with an xorshift): the
    random order of Seidel's algorithm, the same on every call so that answers are
    reproducible to the last bit."""
    for k in range(m):
        out[k] = k
    state = np.uint64(0x9E3779B97F4A7C15) ^ np.uint64(m)
    for k in range(m - 1, 0, -1):
        state ^= state << np.uint64(13)
        state ^= state >> np.uint64(7)
        state ^= state << np.uint64(17)
        j = int(state % np.uint64(k + 1))
        out[k], out[j] = out[j], out[k]


@kernel
def _on_line(G, h, order, upto, i, w0, r_max, tol, out) -> bool:
    """The point nearest w0 on the line G[i]·w = h[i], inside the disc and the half-planes
    order[:upto]; False when that set is empty."""
    gx, gy = G[i, 0], G[i, 1]
    norm = np.sqrt(gx * gx + gy * gy)
    nx, ny, d = gx / norm, gy / norm, h[i] / norm  # the line: n·w = d, at distance d from 0
    if abs(d) > r_max + tol:
        return False  # the disc misses the line
    half = np.sqrt(max(r_max * r_max - d * d, 0.0))
    px, py, ux, uy = d * nx, d * ny, -ny, nx  # w = p + t u
    lo, hi = -half, half
    for k in range(upto):
        j = order[k]
        denom = G[j, 0] * ux + G[j, 1] * uy
        slack = h[j] - (G[j, 0] * px + G[j, 1] * py)
        scale = np.sqrt(G[j, 0] * G[j, 0] + G[j, 1] * G[j, 1])
        if abs(denom) <= 1e-12 * scale:  # parallel: all of the line or none of it
            if slack < -tol * scale:
                return False
            continue
        t = slack / denom
        if denom > 0:
            hi = min(hi, t)
        else:
            lo = max(lo, t)
        if lo > hi + tol:
            return False
    t = (w0[0] - px) * ux + (w0[1] - py) * uy
    t = min(max(t, lo), hi) if lo <= hi else 0.5 * (lo + hi)
    out[0], out[1] = px + t * ux, py + t * uy
    return True


@kernel
def _on_circle(G, h, m, w0, radius, tol, out) -> bool:
    """The point nearest w0 on the circle ||w|| = radius inside every half-plane; False if none
    (the annulus case: see the module docstring)."""
    best = np.inf
    n0 = np.sqrt(w0[0] * w0[0] + w0[1] * w0[1])
    ux, uy = (w0[0] / n0, w0[1] / n0) if n0 > 0 else (1.0, 0.0)
    for c in range(-1, 2 * m):  # -1: w0's own direction; then each line's two crossings
        if c < 0:
            cx, cy = radius * ux, radius * uy
        else:
            i = c // 2
            norm = np.sqrt(G[i, 0] * G[i, 0] + G[i, 1] * G[i, 1])
            if norm == 0.0:
                continue
            nx, ny, d = G[i, 0] / norm, G[i, 1] / norm, h[i] / norm
            if abs(d) > radius:
                continue
            s = np.sqrt(radius * radius - d * d) * (1.0 if c % 2 == 0 else -1.0)
            cx, cy = d * nx - s * ny, d * ny + s * nx
        ok = True
        for k in range(m):
            if G[k, 0] * cx + G[k, 1] * cy > h[k] + tol * (1.0 + abs(h[k])):
                ok = False
                break
        dist = (cx - w0[0]) ** 2 + (cy - w0[1]) ** 2
        if ok and dist < best:
            best, out[0], out[1] = dist, cx, cy
        if ok and c < 0:
            break  # w0's direction is allowed: nothing is nearer
    return best < np.inf


@kernel
def nearest_in_disc(
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
    into ``out`` (2,); False when the problem is infeasible. ``order``: ``seidel_order(m,
    order)``, the rows' random order (it depends on m alone: a caller that solves many
    problems of the same size computes it once). ``r_max`` may be inf (no disc); ``r_min``
    <= 0 means no inner bound."""
    tol = EPS * (1.0 + r_max if np.isfinite(r_max) else 1.0 + abs(w0[0]) + abs(w0[1]))
    for k in range(m):  # empty rows: 0 <= h or nothing
        if G[k, 0] == 0.0 and G[k, 1] == 0.0 and h[k] < -tol:
            return False
    n0 = np.sqrt(w0[0] * w0[0] + w0[1] * w0[1])
    scale = min(1.0, r_max / n0) if n0 > 0 else 1.0
    out[0], out[1] = w0[0] * scale, w0[1] * scale
    for k in range(m):
        i = order[k]
        gx, gy = G[i, 0], G[i, 1]
        if gx == 0.0 and gy == 0.0:
            continue
        if gx * out[0] + gy * out[1] > h[i] + tol * np.sqrt(gx * gx + gy * gy):
            if not _on_line(G, h, order, k, i, w0, r_max, tol, out):
                return False
    if r_min > 0.0 and out[0] * out[0] + out[1] * out[1] < r_min * r_min:
        return _on_circle(G, h, m, w0, r_min, tol, out)
    return True


@entry
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
    """``nearest_in_disc`` for Python callers, ``order`` scratch (>= m ints) that it fills
    with ``seidel_order`` (compiled code calls ``nearest_in_disc`` directly)."""
    seidel_order(m, order)
    return nearest_in_disc(G, h, m, w0, r_max, r_min, order, out)


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
