"""The paper's sampled selection, kept as the reference (formulations/sampled.md).

On every avoidance plane a polar grid of candidate velocities spans the speed range; candidates
inside a conic section (section 3.1 / 4.2) or outside the limits are dropped, and the one nearest
the preferred velocity wins, confirmed by the exact 3D check and kept at least ``margin`` (m/s)
away from every VO, as the QPs' rows are: never an answer on a VO's boundary."""

from __future__ import annotations

import numpy as np

from ..geometry import AvoidancePlanes, Sections, cone_sections, pyramid_sections
from ..status import Status
from .common import Encounter, Outcome, py_decision_planes
from .fallback import first_safe, py_least_bad, py_polar_grid


def plane_sections(enc: Encounter, planes: AvoidancePlanes) -> tuple[Sections, Sections]:
    """The conic sections of the decision's cones and pyramids on ``planes``."""
    return (
        cone_sections(
            enc.cones, planes, corrections=enc.options.corrections, n_samples=enc.options.n_samples
        ),
        pyramid_sections(enc.pyramids, planes),
    )


def select_sampled(enc: Encounter) -> Outcome:
    cfg = enc.options.config
    planes = py_decision_planes(enc.vos, enc.v_now, cfg)
    grid = py_polar_grid(enc.bounds, cfg)
    xy = np.ascontiguousarray(np.broadcast_to(grid, (len(planes.phi),) + grid.shape))
    inside = np.zeros(xy.shape[:2], dtype=bool)
    for sections in plane_sections(enc, planes):
        if sections.kind.shape[0]:
            inside |= np.any(sections.contains(xy), axis=0)
    v = planes.lift(xy).reshape(-1, 3)
    order = np.flatnonzero(~inside.ravel())
    order = order[np.argsort(enc.deviation(v[order]), kind="stable")]  # nearest first
    k = first_safe(enc, v[order])  # within the limits, the exact 3D check, the margin
    if k is not None:
        best = order[k]
        return Outcome(
            v[best], Status.OPTIMAL, float(planes.phi[best // len(grid)]), {"free": len(order)}
        )
    G3, h3 = enc.linear_bounds()
    worst = py_least_bad(
        enc.vos, planes, np.zeros((0, 3)), enc.position, enc.v_now, G3, h3, enc.bounds, cfg
    )
    return Outcome(worst, Status.INFEASIBLE_MIN_VIOLATION, None, {"free": len(order)})
