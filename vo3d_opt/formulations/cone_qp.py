"""cone_qp — one QP in 3D (formulations/cone_qp.md).

Each VO cone contributes the half-space beyond its tangent plane along the generator nearest the
preferred velocity; each VO pyramid the half-space beyond the supporting face plane that the
preferred velocity is least inside of (or most outside of). Both are supporting planes of a
convex VO, so every feasible velocity is outside every VO. Same speed, altitude and acceleration
bounds as plane_qp; the speed ball is exact on cone-capable backends and an inscribed polytope
elsewhere."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..geometry.pyramid import supporting_faces
from ..solvers import QP
from ..status import Status
from .common import Encounter, Outcome, Solve, py_decision_planes
from .fallback import fallback

#: Rounds: the tangent generator nearest v_pref, then turned about each cone's axis by these angles.
TURNS = (0.0, np.pi, np.pi / 2, -np.pi / 2)


def cone_tangent_halfspaces(enc: Encounter, v0: np.ndarray, turn: float = 0.0):
    """Tangent planes N·(v - apex) >= 0 of every cone along the generator nearest v0, turned by
    ``turn`` about the cone's axis (pi: the opposite side). Inside a protected zone: the escape
    half-space."""
    c = enc.cones
    a = c.axis
    u = v0 - c.apex
    perp = u - np.sum(u * a, axis=1, keepdims=True) * a
    norm = np.linalg.norm(perp, axis=1, keepdims=True)
    # Head-on (v0 on the axis): pass on the right, horizontally, as a convention.
    right = np.cross(a, np.array([0.0, 0.0, 1.0]))
    right = np.where(
        np.linalg.norm(right, axis=1, keepdims=True) > 1e-9, right, np.array([0.0, 1.0, 0.0])
    )
    e_perp = np.where(
        norm > 1e-9,
        perp / np.maximum(norm, 1e-12),
        right / np.linalg.norm(right, axis=1, keepdims=True),
    )
    if turn:  # rotate e_perp about the axis (Rodrigues; e_perp is perpendicular to a)
        e_perp = np.cos(turn) * e_perp + np.sin(turn) * np.cross(a, e_perp)
    N = -c.sin_alpha[:, None] * a + c.cos_alpha[:, None] * e_perp
    N = np.where(c.inside[:, None], -c.rel, N)  # escape: (v - apex)·rel <= 0
    return N, np.sum(N * c.apex, axis=1)


def fibonacci_directions(k: int) -> np.ndarray:
    """k nearly uniform unit vectors."""
    i = np.arange(k) + 0.5
    phi = np.arccos(1 - 2 * i / k)
    theta = np.pi * (1 + 5**0.5) * i
    return np.stack(
        [np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=-1
    )


@lru_cache(maxsize=4)
def _unit_polytope(k: int) -> tuple[np.ndarray, float]:
    D = fibonacci_directions(k)
    probe = fibonacci_directions(20000)
    rho = np.max(np.arccos(np.clip(np.max(probe @ D.T, axis=1), -1, 1)))
    return D, float(np.cos(rho) * 0.995)  # margin for the sampled covering angle


def speed_polytope(radius: float, k: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """A polytope inside the ball |v| <= radius: n_i·v <= radius cos(rho), rho the covering
    angle of the directions: every vertex then lies within the ball."""
    D, c = _unit_polytope(k)
    return D, np.full(k, radius * c)


def build_qp(
    enc: Encounter, has_cones: bool, turn: float = 0.0, included: np.ndarray | None = None
) -> QP:
    """The 3D QP with the half-spaces of the ``included`` VOs (cones first, then pyramids;
    all when None)."""
    n = enc.cones.n
    inc = np.ones(n + enc.pyramids.n, dtype=bool) if included is None else included
    rows_G, rows_h = [], []
    if n and inc[:n].any():
        N, b = cone_tangent_halfspaces(enc, enc.v_pref, turn)
        rows_G.append(-N[inc[:n]])
        rows_h.append(-b[inc[:n]] - enc.options.margin)
    if enc.pyramids.n and inc[n:].any():
        N, b = supporting_faces(enc.pyramids, enc.v_pref)
        rows_G.append(-N[inc[n:]])
        rows_h.append(-b[inc[n:]] - enc.options.margin)
    G3, h3 = enc.qp_bounds()
    rows_G.append(G3)
    rows_h.append(h3)
    if not has_cones:
        Gs, hs = speed_polytope(enc.limits.v_max)
        rows_G.append(Gs)
        rows_h.append(hs)
    return QP(
        P=2.0 * np.eye(3),
        q=-2.0 * enc.v_pref,
        G=np.vstack(rows_G),
        h=np.concatenate(rows_h),
        soc_radius=enc.limits.v_max if has_cones else None,
    )


def select_cone_qp(enc: Encounter, solve: Solve, has_cones: bool) -> Outcome:
    """For each turn of the cone tangents: solve with the half-spaces of the VOs that hold v_pref
    (and the zones A is inside), add those of the VOs the answer enters, and repeat until the
    answer is safe or the QP infeasible (constraint generation, at most one round per VO).
    The safe answer nearest v_pref over the turns wins."""
    tried, failed, attempts, best = [], 0, 0, None
    start = enc.pref_in | enc.inside
    for turn in TURNS if enc.cones.n else TURNS[:1]:
        included = start.copy()
        while True:
            res = solve(build_qp(enc, has_cones, turn, included))
            attempts += 1
            if not (res.ok and res.x is not None and res.x.shape == (3,)):
                failed += res.status == "failed"
                break
            tried.append(res.x)
            entered = enc.containing(res.x)[:, 0]
            if not entered.any():
                if enc.within_limits(res.x)[0] and (
                    best is None or enc.deviation(res.x)[0] < enc.deviation(best[0])[0]
                ):
                    best = (res.x, turn)
                break
            if np.all(included[entered]):
                break
            included |= entered
    if best is not None:
        return Outcome(
            best[0],
            Status.OPTIMAL,
            None,
            {"round": f"turn {np.degrees(best[1]):.0f}", "solved": attempts},
        )
    return fallback(
        enc,
        py_decision_planes(enc.vos, enc.v_now, enc.options.config),
        np.array(tried).reshape(-1, 3),
        failed == attempts,
    )
