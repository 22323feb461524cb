"""The fallbacks every formulation shares, compiled: the sampled reference's polar grid on the
avoidance planes (the paper's candidates), the first of them that is safe by the exact check
with the margin kept, and the least-bad velocity when nothing is safe.

The compiled kernel calls ``grid_search`` and ``least_bad`` directly; the Python formulations
(``sampled``, ``plane_qp`` on outside backends, ``cone_qp``, ``nlp``) through ``fallback`` and
``first_safe``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._jit import entry, inline, jit
from ..geometry import AvoidancePlanes
from ..geometry.membership import ball_in_cone, clearance, in_cone, in_pyramid
from ..status import Status
from .common import (
    FINE_HEADING_STEP,
    FINE_SPEED_LEVELS,
    NEVER,
    Bounds,
    Config,
    Encounter,
    Outcome,
    VOs,
    closing_rate,
    time_to_intrusion,
    vz_range,
    within_limits,
    zone_time_bound,
)


@jit
def _polar(bounds: Bounds, L: int, heading_step: float) -> tuple[np.ndarray, np.ndarray]:
    """``polar_grid``'s points (L speeds, a heading every ``heading_step`` rad) and, for each,
    its speed level and heading index (M, 2)."""
    H = int(np.ceil(2.0 * np.pi / heading_step - 1e-9))
    out, where = np.empty((L * H, 2)), np.empty((L * H, 2), dtype=np.int64)
    cos_h, sin_h = np.empty(H), np.empty(H)  # per heading, not per point: most of the cost
    for k in range(H):
        cos_h[k], sin_h[k] = np.cos(k * heading_step), np.sin(k * heading_step)
    m = 0
    for a in range(L):
        s = bounds.v_min + (bounds.v_max - bounds.v_min) * a / (L - 1)
        if a > 0 and s == bounds.v_min + (bounds.v_max - bounds.v_min) * (a - 1) / (L - 1):
            continue
        for k in range(1 if s == 0.0 else H):  # rounded as numpy's round(12) does
            out[m, 0] = np.rint(s * cos_h[k] * 1e12) / 1e12
            out[m, 1] = np.rint(s * sin_h[k] * 1e12) / 1e12
            where[m, 0], where[m, 1] = a, k
            m += 1
    return out[:m], where[:m]


@jit
def polar_grid(bounds: Bounds, cfg: Config) -> np.ndarray:
    """(M, 2) in-plane candidates: ``speed_levels`` speeds from v_min to v_max, headings every
    ``heading_step``; speed 0 once, repeated speeds once."""
    return _polar(bounds, cfg.speed_levels, cfg.heading_step)[0]


class Grid(NamedTuple):
    """``polar_grid`` in blocks of neighbouring points (BLOCK speeds by BLOCK headings), each
    with a disc that holds them: a VO that holds a block's disc on a plane holds each of its
    points there (``ball_in_cone``), so the fallbacks skip them without checking them one by
    one. In a crowd almost every block lies in some VO."""

    points: np.ndarray  # (M, 2) the in-plane candidates
    block: np.ndarray  # (M,) int64: each point's block
    discs: np.ndarray  # (B, 3) each block's disc in plane coordinates: centre x, y, radius


#: Speed levels and headings per block side. 3 x 3: in the sphere swap's least-bad decisions
#: 96 % of the grid's points lie in a block inside a VO cone (a prototype gave 80 % for 3 x 6).
BLOCK = 3


@jit
def has_hazard(vos: VOs, nbrs: np.ndarray) -> bool:
    """Whether the decision has something that does not avoid: an obstacle's VO pyramid in
    reach or a non-cooperative neighbour (``nbrs`` column 7 is 0)."""
    if vos.pyramids.L_pz.shape[0] > 0:
        return True
    for i in range(nbrs.shape[0]):
        if not nbrs[i, 7] > 0.0:
            return True
    return False


@jit
def grid_of(bounds: Bounds, cfg: Config, hazard: bool) -> Grid:
    """The fallbacks' polar grid of one decision and its blocks: ``cfg``'s, but with
    ``fine_fallback`` and a ``hazard`` (``has_hazard``) with at least the default grid's speeds
    and headings (``FINE_SPEED_LEVELS``, ``FINE_HEADING_STEP``; a no-op with the default grid).
    Denser, not a superset: 45° headings, for one, are not on a 10° grid."""
    L, step = cfg.speed_levels, cfg.heading_step
    if hazard and cfg.fine_fallback:
        L, step = max(L, FINE_SPEED_LEVELS), min(step, FINE_HEADING_STEP)
    points, where = _polar(bounds, L, step)
    M, per_row = points.shape[0], (where[:, 1].max() // BLOCK + 1) if points.shape[0] else 1
    block = np.empty(M, dtype=np.int64)
    for m in range(M):
        block[m] = (where[m, 0] // BLOCK) * per_row + where[m, 1] // BLOCK
    B = block.max() + 1 if M else 0
    discs, count = np.zeros((B, 3)), np.zeros(B)
    for m in range(M):  # centres: the mean of the members
        for j in range(2):
            discs[block[m], j] += points[m, j]
        count[block[m]] += 1.0
    for b in range(B):
        for j in range(2):
            discs[b, j] /= max(count[b], 1.0)
    for m in range(M):  # radii: the farthest member, widened beyond the rounding of a lift
        b = block[m]
        d = np.sqrt((points[m, 0] - discs[b, 0]) ** 2 + (points[m, 1] - discs[b, 1]) ** 2)
        discs[b, 2] = max(discs[b, 2], d * (1.0 + 1e-9) + 1e-9)
    return Grid(points, block, discs)


@inline
def _in_any(vos: VOs, v: np.ndarray, horizon: float, hint: np.ndarray) -> bool:
    """Whether some VO holds v (the exact 3D check), starting with hint[0], the VO that held
    the last velocity checked: in a crowd most grid points fail on the same VO, so this
    skips most of the checks without changing any answer. 0 <= hint[0] < the VO count (a
    fresh hint per decision: it indexes these VOs)."""
    n = vos.cones.d_oi.shape[0]
    count = n + vos.pyramids.L_pz.shape[0]
    k = hint[0]
    for _ in range(count):  # k wraps round by hand: a modulo per point costs more than a check
        inside = (
            in_cone(vos.cones, k, v, horizon, 0.0)
            if k < n
            else in_pyramid(vos.pyramids, k - n, v, horizon)
        )
        if inside:
            hint[0] = k
            return True
        k = k + 1 if k + 1 < count else 0
    return False


@inline
def safe_by_margin(
    vos: VOs,
    v: np.ndarray,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    cfg: Config,
    hint: np.ndarray,
) -> bool:
    """Within the limits, outside every VO by the exact check, and at least ``margin`` (m/s)
    from every VO: the same margin the linearised rows keep, so no answer lies on a VO's
    boundary. ``hint`` (1,) int: see ``_in_any``."""
    if not within_limits(v, G3, h3, bounds) or _in_any(vos, v, cfg.horizon, hint):
        return False
    return clearance(vos.cones, vos.pyramids, v, cfg.horizon) >= cfg.margin * (1.0 - 1e-9)


@inline
def _disc_centre(planes: AvoidancePlanes, grid: Grid, b: int, p: int, c: np.ndarray) -> None:
    """Block b's disc centre on plane p, in 3D into ``c``, lifted as a grid point is."""
    T = planes.to_plane
    for j in range(3):
        c[j] = grid.discs[b, 0] * T[0, 0, j] + grid.discs[b, 1] * T[p, 1, j]


@inline
def _covered(
    vos: VOs, planes: AvoidancePlanes, grid: Grid, b: int, p: int, c: np.ndarray, hint: np.ndarray
) -> bool:
    """Whether some VO cone holds block b's disc on plane p (``ball_in_cone``), trying first
    hint[0], the cone that held the last block (0 <= hint[0] < the cone count). ``c`` (3,):
    scratch for the disc's centre."""
    n = vos.cones.d_oi.shape[0]
    _disc_centre(planes, grid, b, p, c)
    k = hint[0]
    for _ in range(n):
        if ball_in_cone(vos.cones, k, c, grid.discs[b, 2]):
            hint[0] = k
            return True
        k = k + 1 if k + 1 < n else 0
    return False


@jit
def grid_search(
    vos: VOs,
    planes: AvoidancePlanes,
    grid: Grid,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    cfg: Config,
    cover: np.ndarray,
) -> tuple[bool, np.ndarray, int]:
    """The velocity of ``grid`` on the planes nearest the preferred one that ``safe_by_margin``
    accepts: (found, velocity, plane index). Grid points equally far from it are tried plane
    by plane. A point whose block lies in a VO cone on that plane is not safe: it is skipped
    (the block is looked at once, when the first of its points comes up; without a horizon
    only, the cones' certificate's condition). ``cover`` (planes, blocks) int64, filled: the
    cone that holds each block on each plane, -1 none, -2 not looked at (for ``least_bad``)."""
    T, points = planes.to_plane, grid.points
    w0 = T[0, 0, 0] * vos.v_pref[0] + T[0, 0, 1] * vos.v_pref[1] + T[0, 0, 2] * vos.v_pref[2]
    dev = np.empty(points.shape[0])
    for g in range(points.shape[0]):  # |v - v_pref|: the planes are isometric
        dev[g] = np.sqrt((points[g, 0] - w0) ** 2 + points[g, 1] ** 2)
    order = np.argsort(dev, kind="mergesort")  # stable: equal deviations in grid order
    hint, block_hint = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)
    cover[:, :] = -2
    by_block = cfg.horizon < 0.0 and vos.cones.d_oi.shape[0] > 0
    v, c = np.empty(3), np.empty(3)
    a = 0
    while a < order.shape[0]:
        b = a
        while b < order.shape[0] and dev[order[b]] <= dev[order[a]] + 1e-12:
            b += 1
        for p in range(planes.phi.shape[0]):
            for q in range(a, b):
                x, y = points[order[q], 0], points[order[q], 1]
                if y == 0.0 and p > 0:  # on e1, the same velocity on every plane: tried on 0
                    continue
                if by_block:
                    k = grid.block[order[q]]
                    if cover[p, k] == -2:
                        in_one = _covered(vos, planes, grid, k, p, c, block_hint)
                        cover[p, k] = block_hint[0] if in_one else -1
                    if cover[p, k] >= 0:
                        continue
                for j in range(3):  # e1 is the same on every plane
                    v[j] = x * T[0, 0, j] + y * T[p, 1, j]
                if safe_by_margin(vos, v, G3, h3, bounds, cfg, hint):
                    return True, v, p
        a = b
    return False, v, -1


@inline
def _consider(
    vos: VOs,
    v: np.ndarray,
    clip: bool,
    v_now: np.ndarray,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    best: np.ndarray,
    key: np.ndarray,
    hint: np.ndarray,
    escape: bool,
) -> None:
    """Keep v (first clipped into the reachable box |v - v_now| <= a·dt if ``clip``) in
    ``best`` if it is within the limits and its (latest intrusion, slowest closing, least
    deviation) beats the best's, stored in ``key`` as (-time, deviation, closing). The
    closing rate on the zones A is inside counts only with ``escape`` (``least_bad_escape``)
    and only among velocities that enter a zone at once (time 0); else it is 0 for all."""
    if clip:
        dv = bounds.acceleration * bounds.dt
        for c in range(3):
            v[c] = min(max(v[c], v_now[c] - dv), v_now[c] + dv)
    if not within_limits(v, G3, h3, bounds):
        return
    # A velocity whose intrusion comes before the best one's cannot win: its time is only
    # computed far enough to know that (the answer is the same, most grid points cost less).
    t = -min(time_to_intrusion(vos, v, -key[0], hint), NEVER)
    if t > key[0]:
        return
    dev = np.sqrt(
        (v[0] - vos.v_pref[0]) ** 2 + (v[1] - vos.v_pref[1]) ** 2 + (v[2] - vos.v_pref[2]) ** 2
    )
    cl = closing_rate(vos, v) if escape and t == 0.0 else 0.0
    if t < key[0] or (t == key[0] and (cl < key[2] or (cl == key[2] and dev < key[1]))):
        best[0], best[1], best[2] = v[0], v[1], v[2]
        key[0], key[1], key[2] = t, dev, cl


@inline
def _block_time(
    vos: VOs, planes: AvoidancePlanes, grid: Grid, b: int, p: int, c: np.ndarray, k: int
) -> float:
    """``zone_time_bound`` of block b's disc on plane p for zone k, the zone that beat the last
    grid point (inf when k is a pyramid). ``c`` (3,): scratch for the disc's centre."""
    if k >= vos.cones.d_oi.shape[0]:
        return np.inf
    _disc_centre(planes, grid, b, p, c)
    return zone_time_bound(vos, k, c, grid.discs[b, 2])


@jit
def least_bad(
    vos: VOs,
    planes: AvoidancePlanes,
    grid: Grid,
    cover: np.ndarray,
    tried: np.ndarray,
    p: np.ndarray,
    v_now: np.ndarray,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> np.ndarray:
    """Among the tried answers (k, 3), ``grid`` on every plane, zero and v_now, within the
    limits, the velocity whose first protected-zone intrusion comes latest (ties at once,
    inside zones: first the one closing slowest on them, with ``least_bad_escape``, the
    default: without it, among velocities that all close on a zone A is inside, the nearest
    the preferred one may fly straight at a neighbour; then nearest the preferred velocity).
    With an acceleration limit each is also tried clipped into the reachable box (few grid
    points lie in it). None within the limits (e.g. v_min > 0 and zero): the limits' own
    closest point to hovering.
    ``cover``: the cone that holds each block on each plane, as ``grid_search`` leaves it (< 0:
    none known); a block is skipped once a zone's time bound for it (that cone's, or the
    zone's that beat the last point) comes before the best so far (the answer is the same, in
    the same order)."""
    T, points = planes.to_plane, grid.points
    best, key, hint = np.empty(3), np.empty(3), np.zeros(1, dtype=np.int64)
    best[0], key[0], key[1], key[2] = np.nan, np.inf, np.inf, np.inf
    escape = cfg.least_bad_escape
    v, centre, n = np.empty(3), np.empty(3), vos.cones.d_oi.shape[0]
    # per plane and block: a time by which each of its points enters a zone, by the cone that
    # holds it and the zones that beat a grid point just before one of its points came up
    # (the last tried in by_zone, -1 before its first point): a point that enters before the
    # best so far cannot win, and the best only gets later, so the block is skipped from then
    # on (the answer is the same, in the same order)
    by = np.full((planes.phi.shape[0], grid.discs.shape[0]), np.inf)
    by_zone = np.full((planes.phi.shape[0], grid.discs.shape[0]), -1, dtype=np.int64)
    for pass_ in range(1 if np.isnan(bounds.acceleration) else 2):
        clip = pass_ == 1  # the second pass: each clipped into the reachable box
        # in this order: the tried answers, the grid plane by plane, zero, v_now (plain loops:
        # an index split into plane and point by division costs more than the check)
        for q in range(tried.shape[0]):
            for c in range(3):
                v[c] = tried[q, c]
            _consider(vos, v, clip, v_now, G3, h3, bounds, best, key, hint, escape)
        for pl in range(planes.phi.shape[0]):
            for g in range(points.shape[0]):
                if points[g, 1] == 0.0 and pl > 0:  # on e1: plane 0's velocity, its key no better
                    continue
                if not clip and n > 0:  # its block enters a zone before the best so far: skip
                    b = grid.block[g]
                    if by_zone[pl, b] == -1 and cover[pl, b] >= 0:  # first, the cone holding it
                        by[pl, b] = _block_time(vos, planes, grid, b, pl, centre, cover[pl, b])
                        by_zone[pl, b] = cover[pl, b]
                    if by[pl, b] < -key[0]:  # skipped for good: the best only gets later
                        continue
                    if by_zone[pl, b] != hint[0]:  # a zone not tried on this block yet
                        t = _block_time(vos, planes, grid, b, pl, centre, hint[0])
                        by[pl, b], by_zone[pl, b] = min(by[pl, b], t), hint[0]
                        if by[pl, b] < -key[0]:
                            continue
                for c in range(3):
                    v[c] = points[g, 0] * T[pl, 0, c] + points[g, 1] * T[pl, 1, c]
                _consider(vos, v, clip, v_now, G3, h3, bounds, best, key, hint, escape)
        for c in range(3):
            v[c] = 0.0
        _consider(vos, v, clip, v_now, G3, h3, bounds, best, key, hint, escape)
        for c in range(3):
            v[c] = v_now[c]
        _consider(vos, v, clip, v_now, G3, h3, bounds, best, key, hint, escape)
    if np.isnan(best[0]):
        lo, hi = vz_range(p[2], bounds)
        best[0], best[1], best[2] = 0.0, 0.0, min(max(0.0, lo), hi)
    return best


@entry
def py_polar_grid(bounds: Bounds, cfg: Config) -> np.ndarray:
    """``polar_grid`` for Python callers (compiled code calls ``polar_grid``: no Python wrapper)."""
    return polar_grid(bounds, cfg)


@entry
def py_fallback(
    vos: VOs,
    planes: AvoidancePlanes,
    tried: np.ndarray,
    p: np.ndarray,
    v_now: np.ndarray,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    cfg: Config,
    hazard: bool,
) -> tuple[bool, np.ndarray, int]:
    """The kernel's fallbacks for Python callers: ``grid_search``, and when it finds nothing
    ``least_bad`` (with the cones grid_search found holding the blocks), on one ``grid_of``
    (``hazard``: see ``has_hazard``): (found on the grid, velocity, its plane's index or -1)."""
    grid = grid_of(bounds, cfg, hazard)
    cover = np.empty((planes.phi.shape[0], grid.discs.shape[0]), dtype=np.int64)
    found, v, plane = grid_search(vos, planes, grid, G3, h3, bounds, cfg, cover)
    if found:
        return True, v, plane
    return False, least_bad(vos, planes, grid, cover, tried, p, v_now, G3, h3, bounds, cfg), -1


@entry
def py_has_hazard(vos: VOs, nbrs: np.ndarray) -> bool:
    """``has_hazard`` for Python callers."""
    return has_hazard(vos, nbrs)


@entry
def py_least_bad(
    vos: VOs,
    planes: AvoidancePlanes,
    tried: np.ndarray,
    p: np.ndarray,
    v_now: np.ndarray,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> np.ndarray:
    """``least_bad`` on ``cfg``'s own grid for Python callers (``sampled``, whose candidates
    that grid is; compiled code calls ``least_bad``: no Python wrapper)."""
    grid = grid_of(bounds, cfg, False)
    cover = np.full((planes.phi.shape[0], grid.discs.shape[0]), -2, dtype=np.int64)
    return least_bad(vos, planes, grid, cover, tried, p, v_now, G3, h3, bounds, cfg)


@entry
def _first_safe(
    vos: VOs, v: np.ndarray, G3: np.ndarray, h3: np.ndarray, bounds: Bounds, cfg: Config
) -> int:
    hint = np.zeros(1, dtype=np.int64)
    for k in range(v.shape[0]):
        if safe_by_margin(vos, v[k], G3, h3, bounds, cfg, hint):
            return k
    return -1


# ------------------------------------------------------------------------------- Python side


def first_safe(enc: Encounter, candidates: np.ndarray) -> int | None:
    """Index of the first candidate (in the given order) that is within the limits, outside
    every VO by the exact 3D check and at least ``margin`` from every VO, or None."""
    G3, h3 = enc.linear_bounds()
    v = np.ascontiguousarray(np.asarray(candidates, dtype=float).reshape(-1, 3))
    k = _first_safe(enc.vos, v, G3, h3, enc.bounds, enc.options.config)
    return None if k < 0 else int(k)


def fallback(
    enc: Encounter, planes: AvoidancePlanes, tried: np.ndarray, all_failed: bool
) -> Outcome:
    """No answer passed the exact check: the sampled reference's grid (the exact check and the
    margin decide, not its sections); if none is safe either, the least-bad velocity. When the
    backend failed on every problem the status says so whatever the fallback found."""
    G3, h3 = enc.linear_bounds()
    found, v, p = py_fallback(
        enc.vos,
        planes,
        np.ascontiguousarray(tried, dtype=float).reshape(-1, 3),
        enc.position,
        enc.v_now,
        G3,
        h3,
        enc.bounds,
        enc.options.config,
        py_has_hazard(enc.vos, enc.nbrs),
    )
    if found:
        return Outcome(
            v,
            Status.SOLVER_FAILED_FALLBACK if all_failed else Status.OPTIMAL,
            float(planes.phi[p]),
            {"round": "sampled"},
        )
    status = Status.SOLVER_FAILED_FALLBACK if all_failed else Status.INFEASIBLE_MIN_VIOLATION
    return Outcome(v, status, None, {"round": "least_bad"})
