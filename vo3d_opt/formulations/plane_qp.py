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

import numpy as np

from ..geometry.sections import CIRCLE, ELLIPSE, HYPERBOLA, INSIDE_CODE, PARABOLA, TRIANGLE, Sections
from .common import Encounter, Outcome, Solve, first_safe, least_bad
from .planes import PlaneSections, plane_sections
from .problem import QP, Result
from .sampled import candidates

CURVED = (CIRCLE, ELLIPSE, PARABOLA, HYPERBOLA)
#: Linearisation rounds: nearest boundary point, then every section passed on its left, right.
ROUNDS = ("near", "left", "right")


def _pick(dist: np.ndarray, side_y: np.ndarray, valid: np.ndarray, mode: str) -> np.ndarray:
    """Index of the chosen boundary candidate along the last axis."""
    mask = valid
    if mode != "near":
        count = np.maximum(np.sum(valid, axis=-1, keepdims=True), 1)
        centre = np.sum(np.where(valid, side_y, 0.0), axis=-1, keepdims=True) / count
        on_side = valid & ((side_y >= centre) if mode == "left" else (side_y <= centre))
        mask = np.where(np.any(on_side, axis=-1, keepdims=True), on_side, valid)
    return np.argmin(np.where(mask, dist, np.inf), axis=-1)


def _curved_halfplanes(enc: Encounter, ps: PlaneSections, w0: np.ndarray, mode: str):
    """Tangent planes of the cones along the chosen generator, restricted to each plane."""
    sec = ps.cones
    n, P = sec.kind.shape
    Q = np.concatenate([sec.curve, sec.chord], axis=2)  # boundary candidates (n, P, K+2, 2)
    tq = np.concatenate([np.broadcast_to(sec.t, (n, P, len(sec.t))), sec.chord_t], axis=2)
    valid = np.isfinite(Q[..., 0])
    with np.errstate(invalid="ignore"):
        dist = np.linalg.norm(Q - w0, axis=-1)
        k = _pick(dist, Q[..., 1], valid, mode)
    t_star = np.take_along_axis(np.nan_to_num(tq), k[..., None], axis=-1)[..., 0]
    N = enc.cones.outward_normals(t_star)  # (n, P, 3)
    a = np.stack([N @ ps.planes.e1, np.einsum("npi,pi->np", N, ps.planes.e2)], axis=-1)
    b = np.einsum("npi,ni->np", N, enc.cones.apex)
    active = np.isin(sec.kind, CURVED) & np.any(valid, axis=-1)
    return a, b, active


def _triangle_halfplanes(sec: Sections, w0: np.ndarray, mode: str):
    """The two boundary lines of a triangle (the generators through the apex in the plane)."""
    A = sec.apex[:, :, None, :]  # (k, P, 1, 2)
    Pts = sec.chord  # (k, P, 2, 2)
    d = Pts - A
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.maximum(np.sum((w0 - A) * d, axis=-1) / np.sum(d * d, axis=-1), 0.0)
        dist = np.linalg.norm(w0 - A - s[..., None] * d, axis=-1)
    valid = np.isfinite(dist)
    i = _pick(np.nan_to_num(dist, nan=np.inf), np.nan_to_num(Pts[..., 1]), valid, mode)
    d_i = np.take_along_axis(d, i[..., None, None], axis=2)[:, :, 0]
    d_j = np.take_along_axis(d, (1 - i)[..., None, None], axis=2)[:, :, 0]
    normal = np.stack([-d_i[..., 1], d_i[..., 0]], axis=-1)
    normal = np.where((np.sum(normal * d_j, axis=-1) > 0)[..., None], -normal, normal)  # away from P_j
    b = np.sum(normal * sec.apex, axis=-1)
    active = (sec.kind == TRIANGLE) & np.all(valid, axis=-1)
    return np.nan_to_num(normal), np.nan_to_num(b), active


def _inside_halfplanes(sec: Sections):
    """Escape half-planes when A is inside a protected zone: not closing in."""
    return -sec.halfplane[..., :2], -sec.halfplane[..., 2], sec.kind == INSIDE_CODE


def section_halfplanes(enc: Encounter, ps: PlaneSections, mode: str = "near"):
    """All VO half-planes a·w >= b on every plane: (a (k, P, 2), b (k, P), active (k, P))."""
    w0 = ps.w_pref
    parts = []
    if len(enc.cones):
        parts += [_curved_halfplanes(enc, ps, w0, mode), _triangle_halfplanes(ps.cones, w0, mode),
                  _inside_halfplanes(ps.cones)]
    if len(enc.pyramids):
        parts += [_triangle_halfplanes(ps.pyramids, w0, mode), _inside_halfplanes(ps.pyramids)]
    if not parts:
        P = len(ps.planes.phi)
        return np.zeros((0, P, 2)), np.zeros((0, P)), np.zeros((0, P), bool)
    a = np.concatenate([p[0] for p in parts])
    b = np.concatenate([p[1] for p in parts]) + enc.options.margin
    active = np.concatenate([p[2] for p in parts])
    return a, b, active


def speed_polygon(radius: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular polygon inscribed in the disc |w| <= radius, as G w <= h."""
    ang = (np.arange(sides) + 0.5) * 2 * np.pi / sides
    return np.stack([np.cos(ang), np.sin(ang)], axis=-1), np.full(sides, radius * np.cos(np.pi / sides))


def plane_qps(enc: Encounter, ps: PlaneSections, mode: str, has_cones: bool) -> list[QP]:
    """One QP per plane in the variables w = (x, y)."""
    a, b, active = section_halfplanes(enc, ps, mode)
    G3, h3 = enc.linear_bounds()
    E = np.stack([np.broadcast_to(ps.planes.e1, ps.planes.e2.shape), ps.planes.e2], axis=-1)  # (P, 3, 2)
    vmax = enc.limits.v_max
    Gs, hs = speed_polygon(vmax, enc.options.polygon_sides) if not has_cones else (np.zeros((0, 2)), np.zeros(0))
    Pm = 2.0 * np.eye(2)
    q = -2.0 * ps.w_pref
    qps = []
    for p in range(len(ps.planes.phi)):
        act = active[:, p]
        G = np.vstack([-a[act, p], G3 @ E[p], Gs])
        h = np.concatenate([-b[act, p], h3, hs])
        qps.append(QP(P=Pm, q=q, G=G, h=h, soc_radius=vmax if has_cones else None))
    return qps


def solve_planes(enc: Encounter, ps: PlaneSections, solve: Solve, has_cones: bool, mode: str):
    """Solve every plane's QP: candidate velocities (k, 3), their plane indices, failures."""
    vs, idx, failed = [], [], 0
    E1, E2 = ps.planes.e1, ps.planes.e2
    for p, qp in enumerate(plane_qps(enc, ps, mode, has_cones)):
        res: Result = solve(qp)
        if res.ok and res.x.shape == (2,):
            vs.append(res.x[0] * E1 + res.x[1] * E2[p])
            idx.append(p)
        elif res.status == "failed":
            failed += 1
    return (np.array(vs).reshape(-1, 3), np.array(idx, dtype=int), failed)


def select(enc: Encounter, solve: Solve, has_cones: bool) -> Outcome:
    """Solve every round (nearest sides, all left, all right) on every plane and keep the safe
    answer nearest the preferred velocity: a section's nearest side is not always the best one
    once the other sections are taken into account."""
    ps = plane_sections(enc)
    vs, planes, rounds, failed = [], [], [], 0
    for mode in ROUNDS:
        v, idx, f = solve_planes(enc, ps, solve, has_cones, mode)
        failed += f
        vs.append(v)
        planes.append(idx)
        rounds += [mode] * len(v)
    v, idx = np.vstack(vs), np.concatenate(planes)
    order = np.argsort(enc.deviation(v), kind="stable")
    k = first_safe(enc, v[order])
    if k is not None:
        best = order[k]
        return Outcome(v[best], "optimal", float(ps.planes.phi[idx[best]]), {"round": rounds[best], "failed": failed})
    return fallback(enc, ps, v, all_failed=failed == len(ROUNDS) * len(ps.planes.phi))


def fallback(enc: Encounter, ps: PlaneSections, tried: np.ndarray, all_failed: bool) -> Outcome:
    """No QP answer passed the exact check: try the sampled reference's candidates; if none is
    safe either, return the least-bad velocity. When the backend failed on every problem the
    status says so whatever the fallback found."""
    v, plane_idx, free = candidates(enc, ps)
    order = np.argsort(enc.deviation(v), kind="stable")
    k = first_safe(enc, v[order])
    reason = "solver_failed_fallback" if all_failed else None
    if k is not None:
        best = order[k]
        return Outcome(v[best], reason or "optimal", float(ps.planes.phi[plane_idx[best]]),
                       {"round": "sampled"})
    return Outcome(least_bad(enc, np.vstack([tried, v])), reason or "infeasible_min_violation", None,
                   {"round": "least_bad"})
