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

from .cone import VOCones
from .pyramid import VOPyramids


def _closest_approach(
    cones: VOCones, v: np.ndarray, horizon: float | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each cone and velocity (n, M): the closest distance of A's relative motion to B's
    centre over t in [0, horizon], the time it happens, and the closing rate (p·u)."""
    u = np.atleast_2d(np.asarray(v, dtype=float))[None, :, :] - cones.apex[:, None, :]
    p = cones.rel[:, None, :]
    uu = np.einsum("nmi,nmi->nm", u, u)
    pu = np.einsum("nmi,nmi->nm", p, u)
    t_star = np.where(uu > 0, np.maximum(pu, 0.0) / np.maximum(uu, 1e-300), 0.0)
    if horizon is not None:
        t_star = np.minimum(t_star, horizon)
    closest = np.linalg.norm(p - u * t_star[..., None], axis=-1)
    return closest, t_star, pu


def cone_penetration(cones: VOCones, v: np.ndarray) -> np.ndarray:
    """How deep each velocity (M, 3) lies inside each cone (n, M): r_pz minus the closest
    distance that A's relative motion comes to B's centre (> 0 means inside)."""
    closest, _, _ = _closest_approach(cones, v, None)
    return cones.r_pz[:, None] - closest


def in_vo_cones(
    cones: VOCones, v: np.ndarray, *, horizon: float | None = None, tol: float = 0.0
) -> np.ndarray:
    """Boolean (n, M): velocity m lies in VO cone n. ``tol`` (m) widens (>0) or shrinks (<0)
    the protected sphere, e.g. to accept boundary velocities."""
    closest, t_star, pu = _closest_approach(cones, v, horizon)
    hit = (closest < (cones.r_pz + tol)[:, None]) & (t_star > 0)
    return np.where(cones.inside[:, None], pu > 0, hit)


def pyramid_entry_time(pyramids: VOPyramids, v: np.ndarray) -> np.ndarray:
    """Time (s) at which the ray p_A + v t enters each prism C_pz (m, M); inf if never."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    w = np.einsum("mij,kj->mki", pyramids.frame, v)  # velocities in each prism frame
    lo, hi = pyramids.lo[:, None, :], pyramids.hi[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = lo / w, hi / w
    still = w == 0  # a zero component: inside the slab forever or never
    in_slab = (lo <= 0) & (hi >= 0)
    t_lo = np.where(still, np.where(in_slab, -np.inf, np.inf), np.minimum(t1, t2))
    t_hi = np.where(still, np.where(in_slab, np.inf, -np.inf), np.maximum(t1, t2))
    t_enter = np.max(t_lo, axis=-1)
    t_exit = np.min(t_hi, axis=-1)
    hit = t_exit > np.maximum(t_enter, 0.0)
    return np.where(hit, np.maximum(t_enter, 0.0), np.inf)


def in_vo_pyramids(
    pyramids: VOPyramids, v: np.ndarray, *, horizon: float | None = None
) -> np.ndarray:
    """Boolean (m, M): velocity k lies in VO pyramid m (its ray enters C_pz)."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    t = pyramid_entry_time(pyramids, v)
    hit = np.isfinite(t) if horizon is None else t <= horizon
    toward = np.einsum("mi,ki->mk", pyramids.frame[:, 0, :], v) > 0  # horizontal, to the centre
    return np.where(pyramids.inside[:, None], toward, hit)
