"""The linearised VO rows of plane_qp, one per VO, plane and round (formulations/plane_qp.md).

On every avoidance plane P_phi the velocity is w = (x, y), v = x e1 + y e2(phi). Each section
of a VO becomes one half-plane G·w <= h on that plane:

- a conic section (circle, ellipse, parabola, hyperbola): the cone's tangent plane along the
  generator through a boundary point of the section (the curve points of eq. (12) and the
  chord points of eq. (17)), restricted to the plane. Round "near" takes the boundary point
  nearest the preferred velocity, "left" / "right" the nearest in the upper / lower half of
  the section. A tangent plane supports the (convex) cone, so no point of the half-plane is in
  the VO, and it is pushed out by ``margin`` (m/s) so that answers are strictly outside;
- a triangle (the apex on the plane, section 3.1.3, and every pyramid section, eq. 19): one of
  its two sides through the apex;
- A inside the zone: the escape half-plane (not closing in), every round.

Blank, point and line sections constrain nothing. The exact solver and every other backend use
these same rows.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._jit import entry, inline, jit
from ..geometry import AvoidancePlanes
from ..geometry.cone import outward_normal
from ..geometry.sections import (
    CIRCLE,
    ELLIPSE,
    HYPERBOLA,
    INSIDE_CODE,
    PARABOLA,
    TRIANGLE,
    Section,
    cone_base_points,
    cone_section,
    pyramid_base_points,
    pyramid_section,
)
from .common import Config, VOs

#: Linearisation rounds: nearest boundary point, then every section passed on its left, right.
ROUNDS = ("near", "left", "right")


@inline
def _pick(sec: Section, K: int, w0: np.ndarray, scratch: np.ndarray) -> tuple[int, int, int]:
    """The boundary candidate each round linearises at, among the curve points of eq. (12)
    (0..K-1) and the chord points of eq. (17) (K, K + 1): "near" the nearest, "left" / "right"
    the nearest in the upper / lower half of the section (by in-plane y about the candidates'
    mean), or the nearest when that half is empty. A candidate exists if its x is not NaN.
    Two passes (the mean and "near", then the half "near" is not in); ``scratch`` (2, K + 2)."""
    dist, side_y = scratch[0], scratch[1]
    count, total, near, d_near = 0, 0.0, 0, np.inf
    for k in range(K + 2):
        qx = sec.curve[0, k] if k < K else sec.chord[k - K, 0]
        qy = sec.curve[1, k] if k < K else sec.chord[k - K, 1]
        side_y[k] = qy
        # squared: only compared; inf (never picked) for a candidate that does not exist
        dist[k] = (qx - w0[0]) ** 2 + (qy - w0[1]) ** 2 if qx == qx else np.inf
        if qx == qx:
            count, total = count + 1, total + qy
        if dist[k] < d_near:
            near, d_near = k, dist[k]
    centre = total / max(count, 1)
    # The nearest is the first of the least distance, so it is also the nearest of its own
    # half: only the other half needs a search (above: y >= centre, below: y <= centre; on
    # the centre line it is in both, and that search finds it again).
    above = side_y[near] >= centre
    other, d_other = -1, np.inf
    for k in range(K + 2):
        if ((side_y[k] <= centre) if above else (side_y[k] >= centre)) and dist[k] < d_other:
            other, d_other = k, dist[k]
    other = other if other >= 0 else near
    return (near, near, other) if above else (near, other, near)


@entry
def py_pick(curve: np.ndarray, chord: np.ndarray, w0: np.ndarray) -> tuple[int, int, int]:
    """``_pick`` for Python callers (tests): the candidates ``curve`` (2, K), ``chord`` (2, 2)
    (rows: points), NaN x where there is none."""
    K = curve.shape[1]
    sec = Section(curve, chord, np.empty((2, 2)), np.empty(2), np.empty(2), np.empty(3))
    return _pick(sec, K, w0, np.empty((2, K + 2)))


@inline
def _triangle_rows(
    apex: np.ndarray, chord: np.ndarray, w0: np.ndarray, G: np.ndarray, h: np.ndarray
) -> bool:
    """Each round's side of a triangle (the generators through its apex) as G[r]·w <= h[r],
    normal away from the other chord point; False when degenerate. With two candidates,
    "near" takes the nearer side, "left" / "right" the upper / lower one (as _pick does)."""
    d0x, d0y = chord[0, 0] - apex[0], chord[0, 1] - apex[1]
    d1x, d1y = chord[1, 0] - apex[0], chord[1, 1] - apex[1]
    if d0x * d0x + d0y * d0y == 0.0 or d1x * d1x + d1y * d1y == 0.0:
        return False  # a side of length zero: the section is a segment (measure zero)
    wx, wy = w0[0] - apex[0], w0[1] - apex[1]
    s0 = max((wx * d0x + wy * d0y) / (d0x * d0x + d0y * d0y), 0.0)
    s1 = max((wx * d1x + wy * d1y) / (d1x * d1x + d1y * d1y), 0.0)
    dist0 = np.sqrt((wx - s0 * d0x) ** 2 + (wy - s0 * d0y) ** 2)
    dist1 = np.sqrt((wx - s1 * d1x) ** 2 + (wy - s1 * d1y) ** 2)
    if not (np.isfinite(dist0) and np.isfinite(dist1)):
        return False
    centre = 0.5 * (chord[0, 1] + chord[1, 1])
    near = 0 if dist0 <= dist1 else 1
    for r in range(G.shape[0]):
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
        length = np.sqrt(dx * dx + dy * dy)  # a unit normal: the margin is then in m/s
        # G·w <= G·apex: the side away from the other chord point
        nx, ny = dy / length, -dx / length
        if nx * ox + ny * oy < 0:
            nx, ny = -nx, -ny
        G[r, 0], G[r, 1], h[r] = nx, ny, nx * apex[0] + ny * apex[1]
    return True


@inline
def _curve_rows(
    vos: VOs,
    i: int,
    sec: Section,
    cfg: Config,
    w0: np.ndarray,
    to_plane: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    scratch: np.ndarray,
) -> bool:
    """Each round's tangent-plane row of cone i's conic section (see the module docstring).
    ``scratch`` (2, K + 2)."""
    K = cfg.t.shape[0]
    picks = _pick(sec, K, w0, scratch)
    c, e1, e2 = vos.cones, to_plane[0], to_plane[1]
    for r in range(G.shape[0]):
        # The cone's tangent plane along that generator (outward normal N), on P_phi: N·v >= N·apex.
        k = picks[r]
        ct = cfg.cos_t[k] if k < K else sec.chord_cs[k - K, 0]
        st = cfg.sin_t[k] if k < K else sec.chord_cs[k - K, 1]
        N0, N1, N2 = outward_normal(c.R[i], c.sin_alpha[i], ct, st)
        G[r, 0] = -(N0 * e1[0] + N1 * e1[1] + N2 * e1[2])
        G[r, 1] = -(N0 * e2[0] + N1 * e2[1] + N2 * e2[2])
        h[r] = -(N0 * c.apex[i, 0] + N1 * c.apex[i, 1] + N2 * c.apex[i, 2])
    return True


class RowWork(NamedTuple):
    """Scratch of ``plane_rows``, allocated once per decision (``row_work``)."""

    sec: Section  # one section at a time
    scratch: np.ndarray  # (2, K + 2) distances and sides of the boundary candidates


@jit
def row_work(K: int) -> RowWork:
    return RowWork(
        Section(
            np.empty((2, K)),
            np.empty((2, 2)),
            np.empty((2, 2)),
            np.empty(2),
            np.empty(2),
            np.empty(3),
        ),
        np.empty((2, K + 2)),
    )


@inline
def vo_base(vos: VOs, k: int, frame: np.ndarray, cfg: Config, out: np.ndarray) -> None:
    """VO k's points in the planes' frame (``cone_base_points`` / ``pyramid_base_points``),
    computed once per VO: each plane then only turns them (eq. 8). ``out`` (3, K + 3)."""
    n = vos.cones.d_oi.shape[0]
    if k < n:
        cone_base_points(vos.cones, k, frame, cfg.cos_t, cfg.sin_t, out)
    else:
        pyramid_base_points(vos.pyramids, k - n, frame, out)


@inline
def plane_rows(
    vos: VOs,
    k: int,
    p: int,
    base: np.ndarray,
    planes: AvoidancePlanes,
    cfg: Config,
    w0: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    work: RowWork,
) -> bool:
    """Every round's row of VO k (cones first, then pyramids) on plane p, G[r]·w <= h[r]
    (G (R, 2), h (R,)); False when the section constrains nothing. ``base``: ``vo_base``."""
    n, sec = vos.cones.d_oi.shape[0], work.sec
    c, s = cfg.cos_phi[p], cfg.sin_phi[p]
    if k < n:
        kind = cone_section(vos.cones, k, base, planes.frame, c, s, cfg.corrections, sec)
    else:
        kind = pyramid_section(vos.pyramids, k - n, base, c, s, sec)
    active = False
    if kind == INSIDE_CODE:  # escape: not closing in, every round
        for r in range(G.shape[0]):
            G[r, 0], G[r, 1], h[r] = sec.halfplane[0], sec.halfplane[1], sec.halfplane[2]
        active = True
    elif kind == TRIANGLE:
        active = _triangle_rows(sec.apex, sec.chord, w0, G, h)
    elif k < n and (kind == CIRCLE or kind == ELLIPSE or kind == PARABOLA or kind == HYPERBOLA):
        active = _curve_rows(vos, k, sec, cfg, w0, planes.to_plane[p], G, h, work.scratch)
    for r in range(G.shape[0]):
        h[r] -= cfg.margin  # strictly outside: pushed out by the margin (m/s)
    return active
