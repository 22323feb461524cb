"""The paper's sampled selection, kept as the reference (formulations/sampled.md).

On every avoidance plane a polar grid of candidate velocities spans the speed range; candidates
inside a conic section (section 3.1 / 4.2) or outside the limits are dropped, and the one nearest
the preferred velocity wins, confirmed by the exact 3D check."""
from __future__ import annotations

import numpy as np

from .common import Encounter, Outcome, first_safe, least_bad
from ..geometry import AvoidancePlanes
from .planes import plane_sections


def polar_grid(enc: Encounter) -> np.ndarray:
    """(M, 2) in-plane candidates: ``speed_levels`` speeds x headings every ``heading_step_deg``."""
    o = enc.options
    speeds = np.linspace(enc.limits.v_min, enc.limits.v_max, o.speed_levels)
    heading = np.deg2rad(np.arange(0.0, 360.0 - 1e-9, o.heading_step_deg))
    grid = speeds[:, None, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)[None]
    return np.unique(grid.reshape(-1, 2).round(12), axis=0)


def grid_velocities(enc: Encounter, planes: AvoidancePlanes) -> tuple[np.ndarray, np.ndarray]:
    """Every grid velocity on every plane, (P·M, 3), and its plane index (P·M,)."""
    grid = polar_grid(enc)
    P = len(planes.phi)
    xy = np.broadcast_to(grid, (P,) + grid.shape)
    plane_idx = np.repeat(np.arange(P), len(grid))
    return planes.lift(xy).reshape(-1, 3), plane_idx


def select(enc: Encounter) -> Outcome:
    ps = plane_sections(enc)
    v, plane_idx = grid_velocities(enc, ps.planes)
    grid = polar_grid(enc)
    free = ~ps.contains(np.broadcast_to(grid, (len(ps.planes.phi),) + grid.shape)).ravel()
    order = np.flatnonzero(free)
    order = order[np.argsort(enc.deviation(v[order]), kind="stable")]  # nearest first
    k = first_safe(enc, v[order])  # within the limits, confirmed by the exact 3D check
    if k is not None:
        best = order[k]
        return Outcome(v[best], "optimal", float(ps.planes.phi[plane_idx[best]]), {"free": len(order)})
    return Outcome(least_bad(enc, v), "infeasible_min_violation", None, {"free": len(order)})
