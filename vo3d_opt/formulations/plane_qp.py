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

import heapq
from dataclasses import replace

import numpy as np

from ..geometry import AvoidancePlanes
from ..geometry.sections import CIRCLE, ELLIPSE, HYPERBOLA, INSIDE_CODE, PARABOLA, TRIANGLE
from .common import Encounter, Outcome, Solve, first_safe, least_bad
from .planes import PlaneSections, decision_planes, plane_sections
from .problem import QP, Result
from .._jit import jit
from .sampled import grid_velocities

CURVED = (CIRCLE, ELLIPSE, PARABOLA, HYPERBOLA)
#: Linearisation rounds: nearest boundary point, then every section passed on its left, right.
ROUNDS = ("near", "left", "right")
#: Bounds within this much (m/s) of the best deviation found cannot improve on it meaningfully.
_TIE = 1e-6


@jit
def _pick(dist: np.ndarray, side_y: np.ndarray, valid: np.ndarray, r: int) -> int:
    """Index of the boundary candidate that round r linearises at: "near" (r = 0) the nearest
    valid one; "left" / "right" (r = 1, 2) the nearest in the upper / lower half of the section
    (by in-plane y about the candidates' mean), or the nearest when that half is empty."""
    count, total = 0, 0.0
    for k in range(dist.shape[0]):
        if valid[k]:
            count, total = count + 1, total + side_y[k]
    centre = total / max(count, 1)
    best, best_side, d_best, d_side = 0, -1, np.inf, np.inf
    for k in range(dist.shape[0]):
        if not valid[k]:
            continue
        if dist[k] < d_best:
            best, d_best = k, dist[k]
        on_side = (r == 1 and side_y[k] >= centre) or (r == 2 and side_y[k] <= centre)
        if on_side and dist[k] < d_side:
            best_side, d_side = k, dist[k]
    return best_side if best_side >= 0 else best


@jit
def _triangle_row(apex: np.ndarray, chord: np.ndarray, w0: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """One of the two boundary lines of a triangle (the generators through its apex), every
    round: the normal points away from the other chord point. False when it is degenerate."""
    dist, side_y, valid = np.empty(2), np.empty(2), np.empty(2, dtype=np.bool_)
    for j in range(2):
        dx, dy = chord[j, 0] - apex[0], chord[j, 1] - apex[1]
        s = max(((w0[0] - apex[0]) * dx + (w0[1] - apex[1]) * dy) / (dx * dx + dy * dy), 0.0)
        dist[j] = np.hypot(w0[0] - apex[0] - s * dx, w0[1] - apex[1] - s * dy)
        valid[j] = np.isfinite(dist[j])
        side_y[j] = chord[j, 1]
    if not (valid[0] and valid[1]):
        return False
    for r in range(a.shape[0]):
        i = _pick(dist, side_y, valid, r)
        dx, dy = chord[i, 0] - apex[0], chord[i, 1] - apex[1]
        nx, ny = -dy, dx
        if nx * (chord[1 - i, 0] - apex[0]) + ny * (chord[1 - i, 1] - apex[1]) > 0:  # away from P_j
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
        ca = np.sqrt(1.0 - sin_alpha[i] ** 2)
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
                    q = curve[i, p, k] if k < K else chord[i, p, k - K]
                    tq[k] = t[k] if k < K else chord_t[i, p, k - K]
                    valid[k] = np.isfinite(q[0])
                    dist[k] = np.hypot(q[0] - w0[0], q[1] - w0[1]) if valid[k] else np.inf
                    side_y[k] = q[1]
                active[i, p] = valid.any()
                if not active[i, p]:
                    continue
                for r in range(a.shape[0]):
                    ts = tq[_pick(dist, side_y, valid, r)]
                    # The cone's tangent plane along that generator (outward normal N), on P_phi.
                    nb0, nb1, nb2 = -sin_alpha[i], ca * np.cos(ts), ca * np.sin(ts)
                    N = R[i, :, 0] * nb0 + R[i, :, 1] * nb1 + R[i, :, 2] * nb2
                    a[r, i, p, 0] = N[0] * e1[0] + N[1] * e1[1] + N[2] * e1[2]
                    a[r, i, p, 1] = N[0] * e2[p, 0] + N[1] * e2[p, 1] + N[2] * e2[p, 2]
                    b[r, i, p] = N[0] * apex[i, 0] + N[1] * apex[i, 1] + N[2] * apex[i, 2]


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


def section_halfplanes(enc: Encounter, ps: PlaneSections):
    """Every round's VO half-planes a·w >= b on every plane, one row per VO (cones first, then
    pyramids): a (R, k, P, 2), b (R, k, P), and which rows apply, active (k, P), the same in
    every round. A section has one kind, so one row: the tangent line of a curved section, a
    side of a triangle, or the escape half-plane when A is inside the zone."""
    n, m, P, R = len(enc.cones), len(enc.pyramids), len(ps.planes.phi), len(ROUNDS)
    a, b = np.zeros((R, n + m, P, 2)), np.zeros((R, n + m, P))
    active = np.zeros((n + m, P), dtype=bool)
    w0, e2 = ps.w_pref, np.ascontiguousarray(ps.planes.e2)
    if n:
        c, sec = enc.cones, ps.cones
        _cone_rows(sec.kind, sec.curve, sec.t, sec.chord, np.nan_to_num(sec.chord_t), sec.apex,
                   sec.halfplane, c.R, c.sin_alpha, c.apex, ps.planes.e1, e2, w0,
                   a[:, :n], b[:, :n], active[:n])
    if m:
        sec = ps.pyramids
        _pyramid_rows(sec.kind, sec.chord, sec.halfplane, w0, a[:, n:], b[:, n:], active[n:])
    a = np.nan_to_num(a)
    return a, np.nan_to_num(b) + enc.options.margin, active


def speed_polygon(radius: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular polygon inscribed in the disc |w| <= radius, as G w <= h."""
    ang = (np.arange(sides) + 0.5) * 2 * np.pi / sides
    return np.stack([np.cos(ang), np.sin(ang)], axis=-1), np.full(sides, radius * np.cos(np.pi / sides))


class PlaneProblems:
    """The (round, plane) QPs of one decision, built lazily. A VO's sections and half-planes
    (every round's, in one vectorised pass) are computed only when the VO joins the QPs: when
    the preferred velocity or an answer lies in it; a round joins the search only when needed,
    its bounds for all planes at once; a QP is built only when it is solved."""

    def __init__(self, enc: Encounter, planes: AvoidancePlanes, has_cones: bool) -> None:
        self.enc, self.planes, self.has_cones = enc, planes, has_cones
        self.v_max = enc.limits.v_max
        self.w0 = np.array([planes.e1 @ enc.v_pref, 0.0])  # v_pref lies in every plane
        G3, h3 = enc.linear_bounds()
        E = np.stack([np.broadcast_to(planes.e1, planes.e2.shape), planes.e2], axis=-1)
        self.G_lim = G3 @ E  # (P, r, 2): altitude and acceleration rows on each plane
        self.h_lim = h3
        self.G_speed, self.h_speed = (np.zeros((0, 2)), np.zeros(0)) if has_cones else \
            speed_polygon(self.v_max, enc.options.polygon_sides)
        lim = (self.G_lim @ self.w0 - h3) / np.maximum(np.linalg.norm(self.G_lim, axis=-1), 1e-12)
        self.base_bound = np.maximum(np.max(lim, axis=1, initial=0.0),
                                     np.max(self.G_speed @ self.w0 - self.h_speed, initial=0.0))
        R, P = len(ROUNDS), len(planes.phi)
        # Half-plane rows of the VOs computed so far: a (R, k, P, 2), b (R, k, P), active (k, P),
        # and the VO (cones first, then pyramids) each row belongs to.
        self.a, self.b = np.zeros((R, 0, P, 2)), np.zeros((R, 0, P))
        self.active, self.owner = np.zeros((0, P), dtype=bool), np.zeros(0, dtype=int)
        self.computed = np.zeros(len(enc.cones) + len(enc.pyramids), dtype=bool)
        self.n_rounds = 0
        inside = np.concatenate([enc.cones.inside, enc.pyramids.inside])
        #: VOs constrained from the start: those holding v_pref, and the zones A is inside.
        self.initial = enc.containing(enc.v_pref)[:, 0] | inside
        self.ensure(self.initial)

    def ensure(self, vos: np.ndarray) -> None:
        """Compute the half-planes of the VOs in ``vos`` that have none yet."""
        new = vos & ~self.computed
        if not new.any():
            return
        n = len(self.enc.cones)
        ci, pi = np.flatnonzero(new[:n]), np.flatnonzero(new[n:])
        sub = replace(self.enc, cones=self.enc.cones.subset(ci), pyramids=self.enc.pyramids.subset(pi))
        a, b, active = section_halfplanes(sub, plane_sections(sub, sub.options.qp_samples, self.planes))
        self.a = np.concatenate([self.a, a], axis=1)
        self.b = np.concatenate([self.b, b], axis=1)
        self.active = np.concatenate([self.active, active])
        self.owner = np.concatenate([self.owner, ci, n + pi])
        self.computed |= new

    def add_round(self, included: np.ndarray) -> list[tuple[float, int, int]]:
        """Let the next round join: (bound, round, plane) for each plane whose QP is not
        infeasible by its bound."""
        r = self.n_rounds
        self.n_rounds += 1
        lb = self.bounds(r, included)
        return [(float(lb[p]), r, int(p)) for p in np.flatnonzero(np.isfinite(lb))]

    def bounds(self, r: int, included: np.ndarray) -> np.ndarray:
        """(P,) lower bounds on every plane's QP deviation in round r (see ``bound``)."""
        a, b = self.a[r], self.b[r]
        act = self.active & included[self.owner][:, None]
        norm = np.maximum(np.linalg.norm(a, axis=-1), 1e-12)
        viol = np.where(act, (b - a @ self.w0) / norm, 0.0)
        lb = np.maximum(self.base_bound, np.max(viol, axis=0, initial=0.0))
        lb[np.any(act & (b / norm > self.v_max), axis=0)] = np.inf
        return lb

    def bound(self, r: int, p: int, included: np.ndarray) -> float:
        """A lower bound on the QP's deviation: the distance from w0 to the farthest violated
        half-plane; inf when a half-plane misses the whole speed disc (infeasible)."""
        act = self.active[:, p] & included[self.owner]
        ap, bp = self.a[r, act, p], self.b[r, act, p]
        norm = np.maximum(np.linalg.norm(ap, axis=-1), 1e-12)
        if np.any(bp / norm > self.v_max):
            return np.inf
        return float(max(self.base_bound[p], np.max((bp - ap @ self.w0) / norm, initial=0.0)))

    def qp(self, r: int, p: int, included: np.ndarray) -> QP:
        act = self.active[:, p] & included[self.owner]
        G = np.vstack([-self.a[r, act, p], self.G_lim[p], self.G_speed])
        h = np.concatenate([-self.b[r, act, p], self.h_lim, self.h_speed])
        return QP(P=2.0 * np.eye(2), q=-2.0 * self.w0, G=G, h=h,
                  soc_radius=self.v_max if self.has_cones else None)


def select(enc: Encounter, solve: Solve, has_cones: bool) -> Outcome:
    """Best-first search over (round, plane) QPs with lazily added VO constraints.

    Rounds: every section linearised at its boundary point nearest the preferred velocity, then
    every section passed on its left, then on its right (the nearest side is not always best
    once the other sections count). A VO's half-plane joins the QPs when v_pref lies in that VO
    or when a QP's answer does (constraint generation: that QP is re-queued), so sections far
    from the answer never over-constrain it, and are never computed. QPs are solved in order of
    a lower bound on their deviation (the distance to the farthest violated half-plane, which
    only grows as constraints join); the search stops once the best safe answer beats every
    remaining bound. The nearest-point round has the smallest bound on each plane (the distance
    from an interior point to any supporting line is at least its distance to the boundary), so
    the later rounds join the search only while a plane's first bound is below the best answer.
    A QP identical to one already solved (a round that changes nothing on a plane) is skipped."""
    problems = PlaneProblems(enc, decision_planes(enc), has_cones)
    planes = problems.planes
    # The VOs constrained so far, shared by every plane: one found on one plane usually bites
    # on the next ones too. Queue entries remember how many were in when their bound was made.
    included = problems.initial.copy()
    queue = [(lb, r, p, p, int(included.sum())) for lb, r, p in problems.add_round(included)]
    first_bounds = [item[0] for item in queue]
    heapq.heapify(queue)
    best, best_dev, tried, failed, attempts, tie = None, np.inf, [], 0, 0, len(queue)
    solved: set[tuple[int, bytes, bytes]] = set()
    while True:
        done = best_dev - _TIE  # bounds this close to the best answer cannot beat it
        if not queue or queue[0][0] >= done:
            if problems.n_rounds < len(ROUNDS) and min(first_bounds, default=np.inf) < done:
                for lb, r, p in problems.add_round(included):
                    tie += 1
                    heapq.heappush(queue, (lb, r, p, tie, int(included.sum())))
                continue
            break
        lb, r, p, _, known = heapq.heappop(queue)
        if known < included.sum():  # stale bound: VOs joined since; re-queue with the new one
            tie += 1
            heapq.heappush(queue, (max(lb, problems.bound(r, p, included)), r, p, tie, int(included.sum())))
            continue
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
        dev = enc.deviation(v)[0]
        if dev >= best_dev:
            continue
        entered = enc.containing(v)[:, 0]
        if not entered.any():
            if enc.within_limits(v)[0]:
                best, best_dev = (v, p, ROUNDS[r]), dev
        elif not np.all(included[entered]):  # constrain the VOs it entered and solve again
            problems.ensure(entered)
            included |= entered
            tie += 1
            heapq.heappush(queue, (problems.bound(r, p, included), r, p, tie, int(included.sum())))
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
