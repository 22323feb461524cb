"""Exact 3D membership of velocities in VO cones and VO pyramids: the ground truth that the tests
and the selector's final safety check use.

A velocity v is in the VO of a moving neighbour when, both keeping their velocities, A's relative
motion enters B's protected sphere at some future time (within ``horizon`` seconds when given):
the infinite collision cone of section 2.1 translated by the apex. It is in the VO of a static
obstacle when the ray p_A + v t, t >= 0, enters the protected prism C_pz.

Inside a protected zone every velocity 'enters' it, so there the VO is defined as the velocities
that still close in: (v - apex)·(p_B - p_A) > 0 for a sphere, and a horizontal component towards
the prism's centre for C_pz. Velocities that leave are the escape set.

``clearance`` measures how far outside every VO a velocity is, in m/s (its distance to the VOs
in velocity space), for candidates that must be strictly outside by a margin.
"""

from __future__ import annotations

import numpy as np

from .._jit import entry, inline, kernel
from .cone import VOCones
from .pyramid import VOPyramids

#: ``horizon`` value meaning "no horizon" in compiled code.
NO_HORIZON = -1.0


@inline
def closest_approach(
    cones: VOCones, i: int, v: np.ndarray, horizon: float
) -> tuple[float, float, float]:
    """(closest distance to B's centre over t in [0, horizon] (horizon < 0: none), its time t*,
    the closing rate p·u) for velocity v against cone i, u = v - apex the relative velocity."""
    return approach(cones.apex[i], cones.rel[i], v, horizon)


@inline
def approach(
    a: np.ndarray, rel: np.ndarray, v: np.ndarray, horizon: float
) -> tuple[float, float, float]:
    """``closest_approach`` from the cone's apex a (3,) and B's position from A, rel (3,)."""
    u0, u1, u2 = v[0] - a[0], v[1] - a[1], v[2] - a[2]
    uu = u0 * u0 + u1 * u1 + u2 * u2
    pu = rel[0] * u0 + rel[1] * u1 + rel[2] * u2
    t = max(pu, 0.0) / max(uu, 1e-300) if uu > 0 else 0.0
    if horizon >= 0.0:
        t = min(t, horizon)
    d0, d1, d2 = rel[0] - u0 * t, rel[1] - u1 * t, rel[2] - u2 * t
    return np.sqrt(d0 * d0 + d1 * d1 + d2 * d2), t, pu


@inline
def in_cone(cones: VOCones, i: int, v: np.ndarray, horizon: float, tol: float) -> bool:
    """Whether v lies in VO cone i (inside the zone: whether it still closes in). ``tol`` (m)
    widens (> 0) or shrinks (< 0) the protected sphere."""
    if cones.inside[i]:
        return closest_approach(cones, i, v, horizon)[2] > 0.0
    return heads_into(cones.apex[i], cones.rel[i], cones.r_pz[i], v, horizon, tol)


@inline
def heads_into(
    a: np.ndarray, rel: np.ndarray, r_pz: float, v: np.ndarray, horizon: float, tol: float
) -> bool:
    """``in_cone`` for a zone A is outside of, from the cone's apex a (3,), B's position from
    A, rel (3,), and its radius: whether v passes within r_pz + tol of B at a positive time."""
    closest, t_star, _ = approach(a, rel, v, horizon)
    return closest < r_pz + tol and t_star > 0.0


@inline
def entry_time(pyramids: VOPyramids, j: int, v: np.ndarray) -> float:
    """Slab test: the time (s) the ray p_A + v t enters prism j ([lo, hi] in its frame); inf if
    never."""
    frame, lo, hi = pyramids.frame[j], pyramids.lo[j], pyramids.hi[j]
    t_enter, t_exit = -np.inf, np.inf
    for a in range(3):
        w = frame[a, 0] * v[0] + frame[a, 1] * v[1] + frame[a, 2] * v[2]
        if w != w:  # NaN: no ray to speak of, it enters nothing
            return np.inf
        if w == 0.0:  # a zero component: inside the slab forever or never
            if not (lo[a] <= 0.0 <= hi[a]):
                return np.inf
        else:
            t1, t2 = lo[a] / w, hi[a] / w
            t_enter = max(t_enter, min(t1, t2))
            t_exit = min(t_exit, max(t1, t2))
    t0 = max(t_enter, 0.0)
    return t0 if t_exit > t0 else np.inf


@inline
def in_pyramid(pyramids: VOPyramids, j: int, v: np.ndarray, horizon: float) -> bool:
    """Whether v lies in VO pyramid j (inside C_pz: whether it heads towards its centre)."""
    if pyramids.inside[j]:
        h = pyramids.frame[j, 0]
        return h[0] * v[0] + h[1] * v[1] + h[2] * v[2] > 0.0
    t = entry_time(pyramids, j, v)
    return t < np.inf if horizon < 0.0 else t <= horizon


@inline
def ball_in_cone(cones: VOCones, i: int, c: np.ndarray, rho: float) -> bool:
    """Whether every velocity within ``rho`` of ``c`` lies in VO cone i without a horizon, with
    a margin that outlasts rounding: ``in_cone`` (tol 0, no horizon) then holds for each of
    them as computed, not only in exact arithmetic. Sufficient, not necessary: False when A is
    inside the zone, when the ball reaches the apex, or near the cone's surface.

    The ball is seen from the apex under the half-angle beta (sin beta = rho / |u|, u = c -
    apex) and its centre at theta from rel, so no velocity in it is farther than theta + beta
    from rel: below 90 degrees it closes in (t* > 0), and its closest approach to B's centre,
    |rel| sin(theta + beta), is below r_pz by 1e-9 (r_pz + |rel|), a million times the
    rounding of ``closest_approach``."""
    if cones.inside[i]:
        return False
    a, rel = cones.apex[i], cones.rel[i]
    u0, u1, u2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    nu = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    nrel = np.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2)
    pu = rel[0] * u0 + rel[1] * u1 + rel[2] * u2
    if not (nu > rho and pu > 0.0 and nrel < np.inf):  # NaN fails too
        return False
    # |u x rel| for the sine, not sqrt(1 - cos^2): no cancellation at small angles
    x0, x1, x2 = u1 * rel[2] - u2 * rel[1], u2 * rel[0] - u0 * rel[2], u0 * rel[1] - u1 * rel[0]
    sin_t = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2) / (nu * nrel)
    cos_t = pu / (nu * nrel)
    sin_b = rho / nu
    cos_b = np.sqrt(1.0 - sin_b * sin_b)
    if not (cos_t * cos_b - sin_t * sin_b > 1e-6):  # theta + beta clearly below 90 degrees
        return False
    r = cones.r_pz[i]
    return nrel * (sin_t * cos_b + cos_t * sin_b) <= r - 1e-9 * (r + nrel)


@entry
def _in_vos_kernel(
    cones: VOCones, pyramids: VOPyramids, v: np.ndarray, horizon: float, tol: float
) -> np.ndarray:
    n = cones.d_oi.shape[0]
    out = np.empty((n + pyramids.L_pz.shape[0], v.shape[0]), dtype=np.bool_)
    for k in range(v.shape[0]):
        for i in range(n):
            out[i, k] = in_cone(cones, i, v[k], horizon, tol)
        for j in range(pyramids.L_pz.shape[0]):
            out[n + j, k] = in_pyramid(pyramids, j, v[k], horizon)
    return out


def _velocities(v: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.atleast_2d(np.asarray(v, dtype=float)))


def _horizon(horizon: float | None) -> float:
    return NO_HORIZON if horizon is None else float(horizon)


def _no_pyramids() -> VOPyramids:
    return VOPyramids(
        np.zeros((0, 3, 3)),
        np.zeros((0, 3)),
        np.zeros((0, 3)),
        np.zeros(0),
        np.zeros(0),
        np.zeros(0, dtype=bool),
    )


def in_vos(
    cones: VOCones, pyramids: VOPyramids, v: np.ndarray, *, horizon: float | None = None
) -> np.ndarray:
    """Boolean (n + m, M): velocity k lies in VO cone i (rows 0..n-1) or pyramid j (rows n..)."""
    return _in_vos_kernel(cones, pyramids, _velocities(v), _horizon(horizon), 0.0)


def in_vo_cones(
    cones: VOCones, v: np.ndarray, *, horizon: float | None = None, tol: float = 0.0
) -> np.ndarray:
    """Boolean (n, M): velocity m lies in VO cone n. ``tol`` (m) widens (>0) or shrinks (<0)
    the protected sphere, e.g. to accept boundary velocities."""
    return _in_vos_kernel(cones, _no_pyramids(), _velocities(v), _horizon(horizon), float(tol))


def in_vo_pyramids(
    pyramids: VOPyramids, v: np.ndarray, *, horizon: float | None = None
) -> np.ndarray:
    """Boolean (m, M): velocity k lies in VO pyramid m (its ray enters C_pz)."""
    from .cone import vo_cones  # an empty cone set

    empty = vo_cones(np.zeros(3), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    return _in_vos_kernel(empty, pyramids, _velocities(v), _horizon(horizon), 0.0)


@entry
def _penetration_kernel(cones: VOCones, v: np.ndarray) -> np.ndarray:
    out = np.empty((cones.d_oi.shape[0], v.shape[0]))
    for i in range(out.shape[0]):
        for k in range(v.shape[0]):
            out[i, k] = cones.r_pz[i] - closest_approach(cones, i, v[k], NO_HORIZON)[0]
    return out


def cone_penetration(cones: VOCones, v: np.ndarray) -> np.ndarray:
    """How deep each velocity (M, 3) lies inside each cone (n, M): r_pz minus the closest
    distance that A's relative motion comes to B's centre (> 0 means inside)."""
    return _penetration_kernel(cones, _velocities(v))


@entry
def _entry_times(pyramids: VOPyramids, v: np.ndarray) -> np.ndarray:
    out = np.empty((pyramids.L_pz.shape[0], v.shape[0]))
    for j in range(out.shape[0]):
        for k in range(v.shape[0]):
            out[j, k] = entry_time(pyramids, j, v[k])
    return out


def pyramid_entry_time(pyramids: VOPyramids, v: np.ndarray) -> np.ndarray:
    """Time (s) at which the ray p_A + v t enters each prism C_pz (m, M); inf if never."""
    return _entry_times(pyramids, _velocities(v))


# ---------------------------------------------------------------------------------- clearance

#: Steps of the ternary search in ``_zone_clearance`` (shrinks the interval by (2/3)^100).
_SEARCH_STEPS = 100


@kernel
def _scaled_zone_distance(
    shape: int, cones: VOCones, pyramids: VOPyramids, k: int, v: np.ndarray, s: float
) -> float:
    """Distance from v to the zone scaled by s about the apex: for cone k (shape 0) the ball
    apex + s·B(rel, r_pz), for pyramid k (shape 1) the prism s·C_pz."""
    if shape == 0:
        a, rel = cones.apex[k], cones.rel[k]
        d0, d1, d2 = v[0] - a[0] - s * rel[0], v[1] - a[1] - s * rel[1], v[2] - a[2] - s * rel[2]
        return max(np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - s * cones.r_pz[k], 0.0)
    total = 0.0
    for ax in range(3):
        f = pyramids.frame[k, ax]
        x = f[0] * v[0] + f[1] * v[1] + f[2] * v[2]
        gap = max(s * pyramids.lo[k, ax] - x, x - s * pyramids.hi[k, ax], 0.0)
        total += gap * gap
    return np.sqrt(total)


@kernel
def _reach(shape: int, cones: VOCones, pyramids: VOPyramids, k: int) -> float:
    """The distance from A to zone k (m): d_oi - r_pz for a sphere, to the prism for C_pz."""
    if shape == 0:
        return cones.d_oi[k] - cones.r_pz[k]
    total = 0.0
    for ax in range(3):
        gap = max(pyramids.lo[k, ax], -pyramids.hi[k, ax], 0.0)
        total += gap * gap
    return np.sqrt(total)


@kernel
def _zone_clearance(
    shape: int, cones: VOCones, pyramids: VOPyramids, k: int, v: np.ndarray, horizon: float
) -> float:
    """The distance (m/s) from v to the VO of zone k in velocity space (0 inside it).

    The VO is the union over times t in (0, horizon] of the velocities that put A in the zone at
    t: apex + Z / t, Z the zone relative to A. With s = 1/t that is the union of the zones
    scaled by s >= 1/horizon, and the distance to it is min over s of the distance to s·Z,
    a convex function of s (the scaled zones form a convex cone in (x, s)): a ternary search
    finds it. Inside the zone the VO is the closing half-space: the escape margin."""
    if shape == 0 and cones.inside[k]:
        rel, a = cones.rel[k], cones.apex[k]
        return -((v[0] - a[0]) * rel[0] + (v[1] - a[1]) * rel[1] + (v[2] - a[2]) * rel[2]) / max(
            cones.d_oi[k], 1e-12
        )
    if shape == 1 and pyramids.inside[k]:
        h = pyramids.frame[k, 0]
        return -(h[0] * v[0] + h[1] * v[1] + h[2] * v[2])
    lo = 1.0 / horizon if horizon > 0.0 else 0.0
    # Beyond s_max the zone is farther than at lo: s·dist(0, Z) - |v - apex| > f(lo).
    f_lo = _scaled_zone_distance(shape, cones, pyramids, k, v, lo)
    reach = _reach(shape, cones, pyramids, k)
    speed = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2) + (
        0.0
        if shape == 1
        else np.sqrt(cones.apex[k, 0] ** 2 + cones.apex[k, 1] ** 2 + cones.apex[k, 2] ** 2)
    )
    hi = max(lo, (f_lo + speed) / max(reach, 1e-12))
    for _ in range(_SEARCH_STEPS):
        m1, m2 = lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0
        if _scaled_zone_distance(shape, cones, pyramids, k, v, m1) <= _scaled_zone_distance(
            shape, cones, pyramids, k, v, m2
        ):
            hi = m2
        else:
            lo = m1
    return min(f_lo, _scaled_zone_distance(shape, cones, pyramids, k, v, 0.5 * (lo + hi)))


@kernel
def clearance(cones: VOCones, pyramids: VOPyramids, v: np.ndarray, horizon: float) -> float:
    """The least distance (m/s) from v to any VO (inf without VOs); <= 0 inside one."""
    best = np.inf
    for i in range(cones.d_oi.shape[0]):
        best = min(best, _zone_clearance(0, cones, pyramids, i, v, horizon))
    for j in range(pyramids.L_pz.shape[0]):
        best = min(best, _zone_clearance(1, cones, pyramids, j, v, horizon))
    return best


@entry
def _clearances(cones: VOCones, pyramids: VOPyramids, v: np.ndarray, horizon: float) -> np.ndarray:
    out = np.empty(v.shape[0])
    for k in range(v.shape[0]):
        out[k] = clearance(cones, pyramids, v[k], horizon)
    return out


def clearances(
    cones: VOCones, pyramids: VOPyramids, v: np.ndarray, *, horizon: float | None = None
) -> np.ndarray:
    """(M,) the least distance (m/s) from each velocity to any VO (inf without VOs)."""
    return _clearances(cones, pyramids, _velocities(v), _horizon(horizon))
