"""The paper's sampled selection, kept as the reference (formulations/sampled.md).

On every avoidance plane a polar grid of candidate velocities spans the speed range; candidates
inside a conic section (section 3.1 / 4.2) or outside the limits are dropped, and the one nearest
the preferred velocity wins, confirmed by the exact 3D check and kept at least ``margin`` (m/s)
away from every VO, as the QPs' rows are: never an answer on a VO's boundary."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from ..config import SelectorConfig
from ..geometry import AvoidancePlanes, Sections, cone_sections, pyramid_sections
from ..status import Status
from .common import FINE_PLANE_STEP_DEG, Encounter, Outcome, py_decision_planes
from .fallback import first_safe, py_least_bad, py_polar_grid

#: VO shapes tested against the grid at once. The test's arrays are (shapes, planes, grid
#: points, section vertices): about 3 MB a shape at the default grid, so chunks, and blocks
#: of grid points within them (``BLOCK`` elements at most), keep a decision's memory bounded
#: (a few hundred MB at most) however many neighbours it has and however fine its grid.
CHUNK = 16
BLOCK = 2_000_000

#: Planes x grid points x section points of one shape's test: the finest grid a decision
#: takes (about 60 times the default's): one neighbour then costs up to about half a second.
MAX_GRID_WORK = 25_000_000


def plane_sections(enc: Encounter, planes: AvoidancePlanes) -> Iterator[Sections]:
    """The conic sections of the decision's cones and pyramids on ``planes``, ``CHUNK``
    shapes at a time."""
    cones, pyramids, chunk = enc.cones, enc.pyramids, CHUNK
    for lo in range(0, cones.n, chunk):
        yield cone_sections(
            cones.subset(np.arange(lo, min(cones.n, lo + chunk))),
            planes,
            corrections=enc.options.corrections,
            n_samples=enc.options.n_samples,
        )
    for lo in range(0, pyramids.n, chunk):
        yield pyramid_sections(pyramids.subset(np.arange(lo, min(pyramids.n, lo + chunk))), planes)


def check_grid(config: SelectorConfig) -> None:
    """``ValueError`` when ``config``'s sampled grid is finer than ``MAX_GRID_WORK`` allows
    (counted from above: planes every ``plane_step_deg`` in [-90, 90], or the default ones
    where ``fine_planes`` gives a decision those, every heading times every speed and the
    origin, the section points)."""
    step = config.planes.plane_step_deg
    if config.safety.fine_planes:
        step = min(step, FINE_PLANE_STEP_DEG)
    planes = math.floor(180.0 / step) + 1
    grid = math.ceil(360.0 / config.sampled.heading_step_deg) * config.sampled.speed_levels + 1
    work = planes * grid * (config.sampled.n_samples + 4)
    if work > MAX_GRID_WORK:
        raise ValueError(
            "plane_step_deg, heading_step_deg, speed_levels, n_samples: the sampled grid "
            f"would test {work:,} points per neighbour, more than {MAX_GRID_WORK:,}; coarsen "
            "one of them"
        )


def _mark_inside(sections: Sections, xy: np.ndarray, inside: np.ndarray) -> None:
    """``inside`` (P, M) |= whether each grid point lies in one of ``sections``, in blocks of
    grid points small enough for ``BLOCK`` (the sections' polygons built once)."""
    polygon = sections.polygon  # (n, P, V, 2)
    per_point = max(1, polygon.shape[0] * polygon.shape[1] * polygon.shape[2])
    step = max(1, BLOCK // per_point)
    for m0 in range(0, xy.shape[1], step):
        block = np.ascontiguousarray(xy[:, m0 : m0 + step])
        inside[:, m0 : m0 + step] |= np.any(sections.contains(block, polygon), axis=0)


def select_sampled(enc: Encounter) -> Outcome:
    cfg = enc.options.config
    planes = py_decision_planes(enc.vos, enc.v_now, cfg)
    grid = py_polar_grid(enc.bounds, cfg)
    xy = np.ascontiguousarray(np.broadcast_to(grid, (len(planes.phi),) + grid.shape))
    inside = np.zeros(xy.shape[:2], dtype=bool)
    for sections in plane_sections(enc, planes):
        _mark_inside(sections, xy, inside)
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
