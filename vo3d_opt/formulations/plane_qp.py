"""plane_qp — the default formulation (formulations/plane_qp.md).

On every avoidance plane P_phi the velocity is w = (x, y) with v = x e1 + y e2(phi). Each
non-blank section becomes one half-plane: the supporting line of the section at the boundary point
nearest the preferred velocity (its tangent plane restricted to P_phi), or, in later rounds, the
nearest point on its left or right side. Supporting lines of a convex section never cut into it,
so every feasible w is outside that VO on that plane. The speed bound is an exact second-order
cone where the backend has cones and an inscribed polygon elsewhere; the altitude bound is
z + v_z dt in [z_min, z_max]. Each plane's QP minimises ||w - w_pref||²; the plane with the least
deviation wins after the exact 3D check, else the next candidate."""
from __future__ import annotations

import functools
import heapq
import math

import numpy as np

from ..geometry import AvoidancePlanes
from ..geometry.cone import outward_normal
from ..geometry.pyramid import BOX_EDGES, prism_corners
from ..geometry.sections import (CIRCLE, CORRECTIONS, ELLIPSE, HYPERBOLA, INSIDE_CODE, PARABOLA, TRIANGLE, generator_angles,
                                 cone_section_arrays, pyramid_section_arrays)
from .common import Encounter, Outcome, Solve, first_safe, least_bad
from .planes import decision_planes
from .problem import QP, Result
from .._jit import jit
from .sampled import grid_velocities

CURVED = (CIRCLE, ELLIPSE, PARABOLA, HYPERBOLA)
#: Linearisation rounds: nearest boundary point, then every section passed on its left, right.
ROUNDS = ("near", "left", "right")
#: Bounds within this much (m/s) of the best deviation found cannot improve on it meaningfully.
_TIE = 1e-6


@jit
def _pick(dist: np.ndarray, side_y: np.ndarray, valid: np.ndarray) -> tuple[int, int, int]:
    """The boundary candidate each round linearises at: "near" the nearest valid one; "left"
    / "right" the nearest in the upper / lower half of the section (by in-plane y about the
    candidates' mean), or the nearest when that half is empty."""
    count, total = 0, 0.0
    for k in range(dist.shape[0]):
        if valid[k]:
            count, total = count + 1, total + side_y[k]
    centre = total / max(count, 1)
    near, left, right = 0, -1, -1
    d_near, d_left, d_right = np.inf, np.inf, np.inf
    for k in range(dist.shape[0]):
        if not valid[k]:
            continue
        if dist[k] < d_near:
            near, d_near = k, dist[k]
        if side_y[k] >= centre and dist[k] < d_left:
            left, d_left = k, dist[k]
        if side_y[k] <= centre and dist[k] < d_right:
            right, d_right = k, dist[k]
    return near, (left if left >= 0 else near), (right if right >= 0 else near)


@jit
def _triangle_row(apex: np.ndarray, chord: np.ndarray, w0: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """One of the two boundary lines of a triangle (the generators through its apex), every
    round: the normal points away from the other chord point. False when it is degenerate.
    With two candidates, "near" takes the nearer side, "left" / "right" the upper / lower one
    (as _pick does)."""
    d0x, d0y = chord[0, 0] - apex[0], chord[0, 1] - apex[1]
    d1x, d1y = chord[1, 0] - apex[0], chord[1, 1] - apex[1]
    wx, wy = w0[0] - apex[0], w0[1] - apex[1]
    s0 = max((wx * d0x + wy * d0y) / (d0x * d0x + d0y * d0y), 0.0)
    s1 = max((wx * d1x + wy * d1y) / (d1x * d1x + d1y * d1y), 0.0)
    dist0, dist1 = np.hypot(wx - s0 * d0x, wy - s0 * d0y), np.hypot(wx - s1 * d1x, wy - s1 * d1y)
    if not (np.isfinite(dist0) and np.isfinite(dist1)):
        return False
    centre = 0.5 * (chord[0, 1] + chord[1, 1])
    near = 0 if dist0 <= dist1 else 1
    for r in range(a.shape[0]):
        i = near
        if r > 0:  # the nearest candidate on the round's side, if there is one
            on0 = chord[0, 1] >= centre if r == 1 else chord[0, 1] <= centre
            on1 = chord[1, 1] >= centre if r == 1 else chord[1, 1] <= centre
            if on0 and on1:
                i = near
            elif on0 or on1:
                i = 0 if on0 else 1
        dx, dy = (d0x, d0y) if i == 0 else (d1x, d1y)
        ox, oy = (d1x, d1y) if i == 0 else (d0x, d0y)
        nx, ny = -dy, dx
        if nx * ox + ny * oy > 0:  # away from the other chord point
            nx, ny = -nx, -ny
        a[r, 0], a[r, 1], b[r] = nx, ny, nx * apex[0] + ny * apex[1]
    return True


@jit
def _cone_rows(kind, curve, t, chord, chord_t, apex_xy, halfplane, R, sin_alpha, apex, e1, e2, w0,
               a, b, active):
    """Every round's half-plane a·w >= b of each cone section on each plane (see select)."""
    n, P, K = curve.shape[0], curve.shape[1], curve.shape[2]
    dist, side_y, valid, tq = np.empty(K + 2), np.empty(K + 2), np.empty(K + 2, dtype=np.bool_), np.empty(K + 2)
    for i in range(n):
        for p in range(P):
            kd = kind[i, p]
            if kd == INSIDE_CODE:  # escape: not closing in, every round
                for r in range(a.shape[0]):
                    a[r, i, p, 0], a[r, i, p, 1], b[r, i, p] = -halfplane[i, p, 0], -halfplane[i, p, 1], -halfplane[i, p, 2]
                active[i, p] = True
            elif kd == TRIANGLE:
                active[i, p] = _triangle_row(apex_xy[i, p], chord[i, p], w0, a[:, i, p], b[:, i, p])
            elif kd == CIRCLE or kd == ELLIPSE or kd == PARABOLA or kd == HYPERBOLA:
                # Boundary candidates: the curve of eq. (12) and the chord points of eq. (17).
                for k in range(K + 2):
                    qx = curve[i, p, k, 0] if k < K else chord[i, p, k - K, 0]
                    qy = curve[i, p, k, 1] if k < K else chord[i, p, k - K, 1]
                    tq[k] = t[k] if k < K else chord_t[i, p, k - K]
                    valid[k] = np.isfinite(qx)
                    dist[k] = np.hypot(qx - w0[0], qy - w0[1]) if valid[k] else np.inf
                    side_y[k] = qy
                active[i, p] = valid.any()
                if not active[i, p]:
                    continue
                picks = _pick(dist, side_y, valid)
                for r in range(a.shape[0]):
                    # The cone's tangent plane along that generator (outward normal N), on P_phi.
                    N0, N1, N2 = outward_normal(R[i], sin_alpha[i], tq[picks[r]])
                    a[r, i, p, 0] = N0 * e1[0] + N1 * e1[1] + N2 * e1[2]
                    a[r, i, p, 1] = N0 * e2[p, 0] + N1 * e2[p, 1] + N2 * e2[p, 2]
                    b[r, i, p] = N0 * apex[i, 0] + N1 * apex[i, 1] + N2 * apex[i, 2]


@jit
def _pyramid_rows(kind, chord, halfplane, w0, a, b, active):
    m, P = kind.shape
    origin = np.zeros(2)  # every pyramid's apex is the velocity origin (eq. 19)
    for j in range(m):
        for p in range(P):
            if kind[j, p] == INSIDE_CODE:
                for r in range(a.shape[0]):
                    a[r, j, p, 0], a[r, j, p, 1], b[r, j, p] = -halfplane[j, p, 0], -halfplane[j, p, 1], 0.0
                active[j, p] = True
            elif kind[j, p] == TRIANGLE:
                active[j, p] = _triangle_row(origin, chord[j, p], w0, a[:, j, p], b[:, j, p])


@jit
def _fill_rows(ci, pi, apex, R, d_vo, r_vo, sin_alpha, rel, inside, p_frame, p_lo, p_hi, p_inside,
               frame, phi, e1, e2, t, flags, w0, margin, a, b, active):
    """Sections (geometry kernels) and every round's half-planes a·w >= b of the cones ``ci``
    and the pyramids ``pi``, written into their rows (cones first, then pyramids)."""
    n, P, NR = apex.shape[0], phi.shape[0], a.shape[0]
    if ci.size:
        kind, _, _, apex_xy, chord, chord_t, _, hp, curve = cone_section_arrays(
            apex[ci], R[ci], d_vo[ci], r_vo[ci], sin_alpha[ci], rel[ci], inside[ci], frame, phi, t,
            flags[0], flags[1], flags[2], flags[3])
        A, B, act = np.zeros((NR, ci.size, P, 2)), np.zeros((NR, ci.size, P)), np.zeros((ci.size, P), dtype=np.bool_)
        _cone_rows(kind, curve, t, chord, chord_t, apex_xy, hp, R[ci], sin_alpha[ci], apex[ci], e1, e2, w0, A, B, act)
        for j in range(ci.size):
            a[:, ci[j]], b[:, ci[j]], active[ci[j]] = A[:, j], B[:, j] + margin, act[j]
    if pi.size:
        kind, chord, _, hp = pyramid_section_arrays(
            prism_corners(p_frame[pi], p_lo[pi], p_hi[pi]), BOX_EDGES, p_frame[pi][:, 0, :].copy(),
            p_inside[pi], frame, phi)
        A, B, act = np.zeros((NR, pi.size, P, 2)), np.zeros((NR, pi.size, P)), np.zeros((pi.size, P), dtype=np.bool_)
        _pyramid_rows(kind, chord, hp, w0, A, B, act)
        for j in range(pi.size):
            a[:, n + pi[j]], b[:, n + pi[j]], active[n + pi[j]] = A[:, j], B[:, j] + margin, act[j]


@jit
def _project2(a1x, a1y, b1, a2x, a2y, b2, wx, wy):
    """The point nearest w in {a1·x >= b1} ∩ {a2·x >= b2} (a closed-form projection: the
    answer is w, its projection on one line, or the lines' crossing); NaN when empty."""
    g1, g2 = a1x * wx + a1y * wy - b1, a2x * wx + a2y * wy - b2
    if g1 >= 0 and g2 >= 0:
        return wx, wy
    n1, n2 = a1x * a1x + a1y * a1y, a2x * a2x + a2y * a2y
    best, bx, by = np.inf, np.nan, np.nan
    if g1 < 0 and n1 > 0:  # onto line 1, if that satisfies row 2
        x, y = wx - g1 / n1 * a1x, wy - g1 / n1 * a1y
        if a2x * x + a2y * y >= b2 - 1e-12:
            best, bx, by = g1 * g1 / n1, x, y
    if g2 < 0 and n2 > 0 and g2 * g2 / n2 < best:  # onto line 2, if that satisfies row 1
        x, y = wx - g2 / n2 * a2x, wy - g2 / n2 * a2y
        if a1x * x + a1y * y >= b1 - 1e-12:
            best, bx, by = g2 * g2 / n2, x, y
    if best < np.inf:
        return bx, by
    det = a1x * a2y - a1y * a2x
    if abs(det) <= 1e-14:
        return np.nan, np.nan
    return (b1 * a2y - b2 * a1y) / det, (a1x * b2 - a2x * b1) / det


@jit
def _bound(a, b, active, included, G_lim, h_lim, G_speed, h_speed, w0, v_max, r, p, ax, ay, rb):
    """A lower bound on the deviation of the QP of round r on plane p, inf when it is
    infeasible: every pair of its rows (VO half-planes and limits) and the speed disc, each
    checked in closed form; with a speed polygon (G_speed, h_speed), also the polygon edge
    that the bounding point crosses, paired with each row. The QP's feasible set lies inside
    each of these sets, so none of them overestimates. ``ax, ay, rb`` are scratch rows (at
    least VOs + limits long)."""
    tol = 1e-9 * (1.0 + v_max)
    wx, wy = w0[0], w0[1]
    k = 0
    for i in range(a.shape[1]):
        if active[i, p] and included[i]:
            ax[k], ay[k], rb[k], k = a[r, i, p, 0], a[r, i, p, 1], b[r, i, p], k + 1
    for j in range(G_lim.shape[1]):  # G w <= h as -G w >= -h
        ax[k], ay[k], rb[k], k = -G_lim[p, j, 0], -G_lim[p, j, 1], -h_lim[j], k + 1
    lb, bx, by = 0.0, wx, wy  # the bound and the point that attains it
    for i in range(k):
        nrm = np.sqrt(ax[i] * ax[i] + ay[i] * ay[i])
        if nrm <= 1e-12:
            if rb[i] > tol:
                lb = np.inf
            continue
        dist = rb[i] / nrm  # signed distance of the line from the origin
        g = ax[i] * wx + ay[i] * wy - rb[i]
        if dist > v_max + tol:  # the half-plane misses the speed disc
            lb = np.inf
            break
        if g < 0:
            # Nearest point of the half-plane within the disc: on the line, the foot of the
            # perpendicular from w0 clamped to the chord the disc cuts.
            fx, fy = dist / nrm * ax[i], dist / nrm * ay[i]
            tx, ty = -ay[i] / nrm, ax[i] / nrm
            half = np.sqrt(max(v_max * v_max - dist * dist, 0.0))
            s = min(max((wx - fx) * tx + (wy - fy) * ty, -half), half)
            d = np.sqrt((fx + s * tx - wx) ** 2 + (fy + s * ty - wy) ** 2)
            if d > lb:
                lb, bx, by = d, fx + s * tx, fy + s * ty
    for i in range(k):
        if lb == np.inf:
            break
        for j in range(i + 1, k):
            if rb[i] > 0 or rb[j] > 0:  # else the origin is in both: the pair meets the disc
                # the pair's least speed: beyond v_max (or NaN, disjoint) means infeasible
                ox, oy = _project2(ax[i], ay[i], rb[i], ax[j], ay[j], rb[j], 0.0, 0.0)
                if not (ox * ox + oy * oy <= (v_max + tol) ** 2):
                    lb = np.inf
                    break
            if ax[i] * wx + ay[i] * wy < rb[i] or ax[j] * wx + ay[j] * wy < rb[j]:  # w0 cut off
                x, y = _project2(ax[i], ay[i], rb[i], ax[j], ay[j], rb[j], wx, wy)
                d = np.sqrt((x - wx) ** 2 + (y - wy) ** 2)
                if d > lb:
                    lb, bx, by = d, x, y
    for _ in range(2 if G_speed.shape[0] and lb < np.inf else 0):
        # The polygon edge the bounding point lies beyond, if any, with each row in turn.
        e, worst = -1, tol
        for j in range(G_speed.shape[0]):
            if G_speed[j, 0] * bx + G_speed[j, 1] * by - h_speed[j] > worst:
                e, worst = j, G_speed[j, 0] * bx + G_speed[j, 1] * by - h_speed[j]
        if e < 0:
            break
        ex, ey, eb = -G_speed[e, 0], -G_speed[e, 1], -h_speed[e]
        for i in range(-1, k):
            ix, iy, ib = (ex, ey, eb) if i < 0 else (ax[i], ay[i], rb[i])  # i = -1: the edge alone
            x, y = _project2(ix, iy, ib, ex, ey, eb, wx, wy)
            d = np.sqrt((x - wx) ** 2 + (y - wy) ** 2)
            if not d <= np.inf:  # NaN: the row and the edge do not meet
                return np.inf
            if d > lb:
                lb, bx, by = d, x, y
    return lb


@jit
def _bounds(a, b, active, included, G_lim, h_lim, G_speed, h_speed, w0, v_max, rounds, planes):
    """``_bound`` of the QPs (rounds[q], planes[q])."""
    out = np.empty(planes.size)
    k_max = a.shape[1] + G_lim.shape[1]
    ax, ay, rb = np.empty(k_max), np.empty(k_max), np.empty(k_max)
    for q in range(planes.size):
        out[q] = _bound(a, b, active, included, G_lim, h_lim, G_speed, h_speed, w0, v_max, rounds[q],
                        planes[q], ax, ay, rb)
    return out


@jit
def _rows_on_planes(G3, to_plane):
    """3D rows G3 (r, 3) on every plane, (P, r, 2): G3 @ [e1, e2(phi)]."""
    out = np.empty((to_plane.shape[0], G3.shape[0], 2))
    for p in range(to_plane.shape[0]):
        for j in range(G3.shape[0]):
            for c in range(2):
                out[p, j, c] = G3[j, 0] * to_plane[p, c, 0] + G3[j, 1] * to_plane[p, c, 1] + G3[j, 2] * to_plane[p, c, 2]
    return out


@jit
def _gather(a, b, active, included, r, p, G_lim, h_lim, G_speed, h_speed):
    """The QP rows G w <= h of round r on plane p: its included VO half-planes, the limits
    and the speed polygon."""
    k = 0
    for i in range(a.shape[1]):
        k += active[i, p] and included[i]
    m = k + G_lim.shape[1] + G_speed.shape[0]
    G, h = np.empty((m, 2)), np.empty(m)
    k = 0
    for i in range(a.shape[1]):
        if active[i, p] and included[i]:
            G[k, 0], G[k, 1], h[k], k = -a[r, i, p, 0], -a[r, i, p, 1], -b[r, i, p], k + 1
    for j in range(G_lim.shape[1]):
        G[k, 0], G[k, 1], h[k], k = G_lim[p, j, 0], G_lim[p, j, 1], h_lim[j], k + 1
    for j in range(G_speed.shape[0]):
        G[k, 0], G[k, 1], h[k], k = G_speed[j, 0], G_speed[j, 1], h_speed[j], k + 1
    return G, h


#: The plane QPs' Hessian: the objective is ||w - w0||² (read-only, shared).
_HESSIAN = 2.0 * np.eye(2)
_HESSIAN.setflags(write=False)


@functools.lru_cache(maxsize=32)
def speed_polygon(radius: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular polygon inscribed in the disc |w| <= radius, as G w <= h (read-only arrays)."""
    ang = (np.arange(sides) + 0.5) * 2 * np.pi / sides
    G, h = np.stack([np.cos(ang), np.sin(ang)], axis=-1), np.full(sides, radius * np.cos(np.pi / sides))
    G.setflags(write=False)
    h.setflags(write=False)
    return G, h


@functools.lru_cache(maxsize=8)
def _all_pairs(rounds: int, planes: int) -> tuple[np.ndarray, np.ndarray]:
    """Every (round, plane) pair as two index arrays, rounds first (read-only)."""
    r, p = np.repeat(np.arange(rounds), planes), np.tile(np.arange(planes), rounds)
    r.setflags(write=False)
    p.setflags(write=False)
    return r, p


@functools.lru_cache(maxsize=8)
def _correction_flags(corrections: frozenset[str] | None) -> np.ndarray:
    """The switches of cone_section_arrays for an Options.corrections value."""
    corr = CORRECTIONS if corrections is None else corrections
    flags = np.array([c in corr for c in ("tg_range", "symmetry_abs", "triangle", "base_chord")])
    flags.setflags(write=False)
    return flags


class PlaneProblems:
    """The (round, plane) QPs of one decision, built lazily. A VO's sections and half-planes
    (every round's, in one compiled pass) are computed only when the VO joins the QPs: when the
    preferred velocity or an answer lies in it; a round joins the search only when needed, its
    bounds for all planes at once; a QP is built only when it is solved."""

    def __init__(self, enc: Encounter, planes: AvoidancePlanes, has_cones: bool) -> None:
        self.enc, self.planes, self.has_cones = enc, planes, has_cones
        self.v_max = enc.limits.v_max
        self.w0 = np.array([float(planes.e1 @ enc.v_pref), 0.0])  # v_pref lies in every plane
        self.q = -2.0 * self.w0  # the objective ||w - w0||² = wᵀw - 2 w0ᵀw + const
        self.q.setflags(write=False)
        G3, h3 = enc.linear_bounds()
        self.G_lim = _rows_on_planes(G3, planes.to_plane)
        self.h_lim = h3
        self.G_speed, self.h_speed = (np.zeros((0, 2)), np.zeros(0)) if has_cones else \
            speed_polygon(self.v_max, enc.options.polygon_sides)
        R, P, V = len(ROUNDS), len(planes.phi), len(enc.cones) + len(enc.pyramids)
        # Half-plane rows, one per VO (cones first, then pyramids): a (R, V, P, 2), b (R, V, P),
        # active (V, P); filled when the VO joins.
        self.a, self.b = np.zeros((R, V, P, 2)), np.zeros((R, V, P))
        self.active = np.zeros((V, P), dtype=bool)
        self.computed = np.zeros(V, dtype=bool)
        self._scratch = np.empty((3, V + len(h3)))
        self._t = generator_angles(enc.options.qp_samples)
        self._flags = _correction_flags(enc.options.corrections)
        #: VOs constrained from the start: those holding v_pref, and the zones A is inside.
        self.initial = enc.pref_in | enc.inside
        self.ensure(self.initial)

    def ensure(self, vos: np.ndarray) -> None:
        """Compute the half-planes of the VOs in ``vos`` that have none yet."""
        new = vos & ~self.computed
        if not new.any():
            return
        n, c, py, pl = len(self.enc.cones), self.enc.cones, self.enc.pyramids, self.planes
        _fill_rows(np.flatnonzero(new[:n]), np.flatnonzero(new[n:]), c.apex, c.R, c.d_vo, c.r_vo,
                   c.sin_alpha, c.rel, c.inside, py.frame, py.lo, py.hi, py.inside, pl.frame, pl.phi,
                   pl.e1, pl.e2, self._t, self._flags, self.w0,
                   self.enc.options.margin, self.a, self.b, self.active)
        self.computed |= new

    def all_bounds(self, included: np.ndarray) -> list[tuple[float, int, int]]:
        """(bound, round, plane) for every QP not proved infeasible by its bound."""
        rounds, planes = _all_pairs(len(ROUNDS), len(self.planes.phi))
        lb = self.bounds(included, rounds, planes).tolist()
        return [(x, r, p) for x, r, p in zip(lb, rounds.tolist(), planes.tolist()) if x < math.inf]

    def bounds(self, included: np.ndarray, rounds: np.ndarray, planes: np.ndarray) -> np.ndarray:
        """Lower bounds on the QP deviations of (rounds[q], planes[q]); inf: infeasible."""
        return _bounds(self.a, self.b, self.active, included, self.G_lim, self.h_lim, self.G_speed,
                       self.h_speed, self.w0, self.v_max, rounds, planes)

    def bound(self, r: int, p: int, included: np.ndarray) -> float:
        return _bound(self.a, self.b, self.active, included, self.G_lim, self.h_lim, self.G_speed,
                      self.h_speed, self.w0, self.v_max, r, p, *self._scratch)

    def qp(self, r: int, p: int, included: np.ndarray) -> QP:
        G, h = _gather(self.a, self.b, self.active, included, r, p, self.G_lim, self.h_lim,
                       self.G_speed, self.h_speed)
        return QP(P=_HESSIAN, q=self.q, G=G, h=h, soc_radius=self.v_max if self.has_cones else None)


def select(enc: Encounter, solve: Solve, has_cones: bool) -> Outcome:
    """Best-first search over (round, plane) QPs with lazily added VO constraints.

    Rounds: every section linearised at its boundary point nearest the preferred velocity, then
    every section passed on its left, then on its right (the nearest side is not always best
    once the other sections count). A VO's half-plane joins a QP when v_pref lies in that VO
    or when that QP's own answer does (constraint generation: the QP is re-queued with it), so
    sections far from the answer never over-constrain it, and are never computed; each QP's
    answer is the same whatever order the QPs are solved in. Every (round, plane) QP is queued
    at once and solved in order of a lower bound on its deviation (``_bound``: each row and
    each pair of rows against the speed disc or polygon, in closed form; it only grows as
    constraints join); the search stops once the best safe answer beats every remaining bound,
    which makes it return what solving every QP would (tests/test_plane_qp.py). The bounds also
    prove most infeasible QPs infeasible without solving them. A QP identical to one already
    solved (a round that changes nothing on a plane) is skipped."""
    problems = PlaneProblems(enc, decision_planes(enc), has_cones)
    planes = problems.planes
    # Each (round, plane) QP has its own constrained VOs: the initial ones and those its own
    # answers entered, so its answer does not depend on the order the QPs are solved in.
    own: dict[tuple[int, int], np.ndarray] = {}
    queue = problems.all_bounds(problems.initial)
    heapq.heapify(queue)
    best, best_dev, tried, failed, attempts = None, np.inf, [], 0, 0
    solved: set[tuple[int, bytes, bytes]] = set()
    while queue and queue[0][0] < best_dev - _TIE:  # closer bounds cannot beat the best answer
        _, r, p = heapq.heappop(queue)
        included = own.get((r, p), problems.initial)
        qp = problems.qp(r, p, included)
        key = (p, qp.G.tobytes(), qp.h.tobytes())
        if key in solved:
            continue
        solved.add(key)
        res: Result = solve(qp)
        attempts += 1
        if not (res.ok and res.x.shape == (2,)):
            failed += res.status == "failed"
            continue
        v = res.x[0] * planes.e1 + res.x[1] * planes.e2[p]
        tried.append(v)
        dev = math.hypot(res.x[0] - problems.w0[0], res.x[1])  # |v - v_pref|: the plane is isometric
        if dev >= best_dev:
            continue
        entered = enc.containing(v)[:, 0]
        if not entered.any():
            if enc.within_limits(v)[0]:
                best, best_dev = (v, p, ROUNDS[r]), dev
        elif not np.all(included[entered]):  # constrain the VOs it entered and solve again
            problems.ensure(entered)
            own[r, p] = included = included | entered
            if np.isfinite(lb := problems.bound(r, p, included)):
                heapq.heappush(queue, (lb, r, p))
    if best is not None:
        v, p, mode = best
        return Outcome(v, "optimal", float(planes.phi[p]), {"round": mode, "solved": attempts})
    return fallback(enc, planes, np.array(tried).reshape(-1, 3), all_failed=attempts > 0 and failed == attempts)


def fallback(enc: Encounter, planes: AvoidancePlanes, tried: np.ndarray, all_failed: bool) -> Outcome:
    """No QP answer passed the exact check: try the sampled reference's grid with the exact check
    (a stronger test than its sections); if none is safe either, return the least-bad velocity.
    When the backend failed on every problem the status says so whatever the fallback found."""
    v, plane_idx = grid_velocities(enc, planes)
    order = np.argsort(enc.deviation(v), kind="stable")
    k = first_safe(enc, v[order])
    reason = "solver_failed_fallback" if all_failed else None
    if k is not None:
        best = order[k]
        return Outcome(v[best], reason or "optimal", float(planes.phi[plane_idx[best]]),
                       {"round": "sampled"})
    return Outcome(least_bad(enc, np.vstack([tried, v])), reason or "infeasible_min_violation", None,
                   {"round": "least_bad"})
