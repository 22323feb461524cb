"""Exact 3D membership of velocities in VO cones and VO pyramids: the ground truth that the tests
and the selector's final safety check use.

A velocity v is in the VO of a moving neighbour when, both keeping their velocities, A's relative
motion enters B's protected sphere at some future time (within ``horizon`` seconds when given):
the infinite collision cone of section 2.1 translated by the apex. It is in the VO of a static
obstacle when the ray p_A + v t, t >= 0, enters the protected prism C_pz.

Inside a protected zone every velocity 'enters' it, so there the VO is defined as the velocities
that still close in: (v - apex)·(p_B - p_A) > 0 for a sphere, and a horizontal component towards
the prism's centre for C_pz. Velocities that leave are the escape set.
"""
from __future__ import annotations

import numpy as np

from .._jit import jit
from .cone import VOCones
from .pyramid import VOPyramids


@jit
def _closest_approach_kernel(apex: np.ndarray, rel: np.ndarray, v: np.ndarray, horizon: float):
    """(n, M) closest distance to B's centre over t in [0, horizon] (horizon < 0: none), its
    time t*, and the closing rate p·u, with u = v - apex the relative velocity."""
    n, M = apex.shape[0], v.shape[0]
    closest, t_star, closing = np.empty((n, M)), np.empty((n, M)), np.empty((n, M))
    for i in range(n):
        for k in range(M):
            u0, u1, u2 = v[k, 0] - apex[i, 0], v[k, 1] - apex[i, 1], v[k, 2] - apex[i, 2]
            uu = u0 * u0 + u1 * u1 + u2 * u2
            pu = rel[i, 0] * u0 + rel[i, 1] * u1 + rel[i, 2] * u2
            t = max(pu, 0.0) / max(uu, 1e-300) if uu > 0 else 0.0
            if horizon >= 0.0:
                t = min(t, horizon)
            d0, d1, d2 = rel[i, 0] - u0 * t, rel[i, 1] - u1 * t, rel[i, 2] - u2 * t
            closest[i, k] = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            t_star[i, k] = t
            closing[i, k] = pu
    return closest, t_star, closing


def _closest_approach(
    cones: VOCones, v: np.ndarray, horizon: float | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each cone and velocity (n, M): the closest distance of A's relative motion to B's
    centre over t in [0, horizon], the time it happens, and the closing rate (p·u)."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    return _closest_approach_kernel(cones.apex, cones.rel, v, -1.0 if horizon is None else float(horizon))


def cone_penetration(cones: VOCones, v: np.ndarray) -> np.ndarray:
    """How deep each velocity (M, 3) lies inside each cone (n, M): r_pz minus the closest
    distance that A's relative motion comes to B's centre (> 0 means inside)."""
    closest, _, _ = _closest_approach(cones, v, None)
    return cones.r_pz[:, None] - closest


@jit
def _in_cones_kernel(apex, rel, r_pz, inside, v, horizon, tol):
    closest, t_star, closing = _closest_approach_kernel(apex, rel, v, horizon)
    out = np.empty(closest.shape, dtype=np.bool_)
    for i in range(closest.shape[0]):
        for k in range(closest.shape[1]):
            if inside[i]:  # inside the zone: the VO is what still closes in
                out[i, k] = closing[i, k] > 0.0
            else:
                out[i, k] = closest[i, k] < r_pz[i] + tol and t_star[i, k] > 0.0
    return out


def in_vo_cones(
    cones: VOCones, v: np.ndarray, *, horizon: float | None = None, tol: float = 0.0
) -> np.ndarray:
    """Boolean (n, M): velocity m lies in VO cone n. ``tol`` (m) widens (>0) or shrinks (<0)
    the protected sphere, e.g. to accept boundary velocities."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    return _in_cones_kernel(cones.apex, cones.rel, cones.r_pz, cones.inside, v,
                            -1.0 if horizon is None else float(horizon), float(tol))


@jit
def _entry_time_kernel(frame: np.ndarray, lo: np.ndarray, hi: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Slab test of the ray p_A + v t against each prism [lo, hi] (in its frame): (m, M)."""
    m, M = frame.shape[0], v.shape[0]
    out = np.empty((m, M))
    for j in range(m):
        for k in range(M):
            t_enter, t_exit = -np.inf, np.inf
            for a in range(3):
                w = frame[j, a, 0] * v[k, 0] + frame[j, a, 1] * v[k, 1] + frame[j, a, 2] * v[k, 2]
                if w != w:  # NaN: no ray to speak of, it enters nothing
                    t_enter = np.inf
                elif w == 0.0:  # a zero component: inside the slab forever or never
                    if not (lo[j, a] <= 0.0 <= hi[j, a]):
                        t_enter = np.inf
                else:
                    t1, t2 = lo[j, a] / w, hi[j, a] / w
                    t_enter = max(t_enter, min(t1, t2))
                    t_exit = min(t_exit, max(t1, t2))
            t0 = max(t_enter, 0.0)
            out[j, k] = t0 if t_exit > t0 else np.inf
    return out


def pyramid_entry_time(pyramids: VOPyramids, v: np.ndarray) -> np.ndarray:
    """Time (s) at which the ray p_A + v t enters each prism C_pz (m, M); inf if never."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    return _entry_time_kernel(pyramids.frame, pyramids.lo, pyramids.hi, v)


@jit
def _in_pyramids_kernel(frame, lo, hi, inside, v, horizon):
    t = _entry_time_kernel(frame, lo, hi, v)
    out = np.empty(t.shape, dtype=np.bool_)
    for j in range(t.shape[0]):
        for k in range(t.shape[1]):
            if inside[j]:  # inside C_pz: a horizontal component towards its centre
                out[j, k] = frame[j, 0, 0] * v[k, 0] + frame[j, 0, 1] * v[k, 1] + frame[j, 0, 2] * v[k, 2] > 0.0
            else:
                out[j, k] = t[j, k] < np.inf if horizon < 0.0 else t[j, k] <= horizon
    return out


def in_vo_pyramids(
    pyramids: VOPyramids, v: np.ndarray, *, horizon: float | None = None
) -> np.ndarray:
    """Boolean (m, M): velocity k lies in VO pyramid m (its ray enters C_pz)."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    return _in_pyramids_kernel(pyramids.frame, pyramids.lo, pyramids.hi, pyramids.inside, v,
                               -1.0 if horizon is None else float(horizon))


@jit
def _in_vos_kernel(apex, rel, r_pz, c_inside, frame, lo, hi, p_inside, v, horizon):
    n = apex.shape[0]
    out = np.empty((n + frame.shape[0], v.shape[0]), dtype=np.bool_)
    out[:n] = _in_cones_kernel(apex, rel, r_pz, c_inside, v, horizon, 0.0)
    out[n:] = _in_pyramids_kernel(frame, lo, hi, p_inside, v, horizon)
    return out


def in_vos(cones: VOCones, pyramids: VOPyramids, v: np.ndarray, *, horizon: float | None = None) -> np.ndarray:
    """Boolean (n + m, M): ``in_vo_cones`` stacked on ``in_vo_pyramids``, in one call."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    return _in_vos_kernel(cones.apex, cones.rel, cones.r_pz, cones.inside, pyramids.frame, pyramids.lo,
                          pyramids.hi, pyramids.inside, v, -1.0 if horizon is None else float(horizon))
