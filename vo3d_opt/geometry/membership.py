"""Exact 3D membership of velocities in VO cones and VO pyramids: the ground truth that the tests
and the selector's final safety check use.

A velocity v is in the VO of a moving neighbour when, both keeping their velocities, A's relative
motion enters B's protected sphere at some future time (within ``horizon`` seconds when given):
the infinite collision cone of section 2.1 translated by the apex. It is in the VO of a static
obstacle when the ray p_A + v t, t >= 0, enters the protected prism C_pz.

Inside a protected zone every velocity 'enters' it, so there the VO is defined as the velocities
that still close in: (v - apex)·(p_B - p_A) > 0 for a sphere, and for C_pz a horizontal component
towards the prism's centre, or, when its top is nearer than its side, a descent too. Velocities
that do neither are the escape set.

``clearances`` measures how far outside every VO a velocity is, in m/s (its distance to the VOs
in velocity space), for candidates that must be strictly outside by a margin. The tests are
compiled (``vo3d_opt._core``; their algorithm reads in ``vo3d_opt/algorithm/vo.hpp`` and
``fallback.hpp``).
"""

from __future__ import annotations

import numpy as np

import vo3d_opt._core as _core

from .cone import VOCones
from .pyramid import VOPyramids

#: ``horizon`` value meaning "no horizon" in compiled code.
NO_HORIZON = -1.0
#: The core's "the obstacles plan with the cones' horizon".
SAME_HORIZON = -2.0


def _velocities(v: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.atleast_2d(np.asarray(v, dtype=float)))


def _horizon(horizon: float | None) -> float:
    return NO_HORIZON if horizon is None else float(horizon)


def _obstacle_horizon(obstacle_horizon: float | None | str) -> float:
    return SAME_HORIZON if obstacle_horizon == "same" else _horizon(obstacle_horizon)  # type: ignore[arg-type]


def in_vos(
    cones: VOCones,
    pyramids: VOPyramids,
    v: np.ndarray,
    *,
    horizon: float | None = None,
    obstacle_horizon: float | None | str = "same",
) -> np.ndarray:
    """Boolean (n + m, M): velocity k lies in VO cone i (rows 0..n-1) or pyramid j (rows n..).
    ``obstacle_horizon``: the pyramids' own horizon (s; None: none); "same": ``horizon``."""
    return _core.in_vos(
        cones,
        pyramids,
        _velocities(v),
        _horizon(horizon),
        0.0,
        obstacle_horizon=_obstacle_horizon(obstacle_horizon),
    )


def in_vo_cones(
    cones: VOCones, v: np.ndarray, *, horizon: float | None = None, tol: float = 0.0
) -> np.ndarray:
    """Boolean (n, M): velocity m lies in VO cone n. ``tol`` (m) widens (>0) or shrinks (<0)
    the protected sphere, e.g. to accept boundary velocities."""
    return _core.in_vos(cones, VOPyramids.empty(), _velocities(v), _horizon(horizon), float(tol))


def in_vo_pyramids(
    pyramids: VOPyramids, v: np.ndarray, *, horizon: float | None = None
) -> np.ndarray:
    """Boolean (m, M): velocity k lies in VO pyramid m (its ray enters C_pz)."""
    return _core.in_vos(VOCones.empty(), pyramids, _velocities(v), _horizon(horizon), 0.0)


def cone_penetration(cones: VOCones, v: np.ndarray) -> np.ndarray:
    """How deep each velocity (M, 3) lies inside each cone (n, M): r_pz minus the closest
    distance that A's relative motion comes to B's centre (> 0 means inside)."""
    return _core.cone_penetration(cones, _velocities(v))


def pyramid_entry_time(pyramids: VOPyramids, v: np.ndarray) -> np.ndarray:
    """Time (s) at which the ray p_A + v t enters each prism C_pz (m, M); inf if never."""
    return _core.entry_times(pyramids, _velocities(v))


def clearances(
    cones: VOCones,
    pyramids: VOPyramids,
    v: np.ndarray,
    *,
    horizon: float | None = None,
    obstacle_horizon: float | None | str = "same",
) -> np.ndarray:
    """(M,) the least distance (m/s) from each velocity to any VO (inf without VOs); <= 0 inside
    one. The VO of a zone is the union over times t in (0, horizon] of the velocities that put
    A in the zone at t; its distance is found by a ternary search over the scale 1/t."""
    return _core.clearances(
        cones,
        pyramids,
        _velocities(v),
        _horizon(horizon),
        obstacle_horizon=_obstacle_horizon(obstacle_horizon),
    )


def clearance_floors(cones: VOCones, v: np.ndarray) -> np.ndarray:
    """(n, M) a lower bound on each cone's part of :func:`clearances` at each velocity, in
    closed form: the distance to the whole cone, which holds the VO whatever the horizon (-inf
    inside the zone). The fallbacks' margin check skips the search for a cone it clears."""
    return _core.clearance_floors(cones, _velocities(v))


def ball_in_cone(cones: VOCones, i: int, c: np.ndarray, rho: float) -> bool:
    """Whether every velocity within ``rho`` of ``c`` lies in VO cone i without a horizon, with
    a margin that outlasts rounding (the exact check then holds for each of them as computed).
    Sufficient, not necessary: False when A is inside the zone, when the ball reaches the apex,
    or near the cone's surface."""
    return bool(_core.ball_in_cone(cones, int(i), np.asarray(c, dtype=float), float(rho)))
