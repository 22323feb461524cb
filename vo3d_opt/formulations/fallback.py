"""The fallbacks every formulation shares, compiled (``vo3d_opt/algorithm/fallback.hpp``): the
fallbacks' polar grid on the avoidance planes (the paper's kind of candidates), the first of
them that is safe by the exact check with the margin kept, and the least-bad velocity when
nothing is safe.

The compiled decision calls ``grid_search`` and ``least_bad`` directly; the Python formulations
(``sampled``, ``plane_qp`` on outside backends, ``cone_qp``, ``nlp``) through ``fallback`` and
``first_safe``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import vo3d_opt._core as _core

from ..geometry import AvoidancePlanes
from ..status import Status
from .common import Bounds, Config, Encounter, Outcome, VOs


class Grid(NamedTuple):
    """``polar_grid`` in blocks of neighbouring points (BLOCK speeds by BLOCK headings), each
    with a disc that holds them: a VO that holds a block's disc on a plane holds each of its
    points there (``ball_in_cone``), so the fallbacks skip them without checking them one by
    one. In a crowd almost every block lies in some VO."""

    points: np.ndarray  # (M, 2) the in-plane candidates
    block: np.ndarray  # (M,) int64: each point's block
    discs: np.ndarray  # (B, 3) each block's disc in plane coordinates: centre x, y, radius


#: Speed levels and headings per block side: small enough that, in a crowd, most blocks lie
#: wholly inside some VO cone and are skipped by one certificate.
BLOCK = 3


def grid_of(bounds: Bounds, cfg: Config, hazard: bool) -> Grid:
    """The fallbacks' polar grid of one decision and its blocks: ``cfg``'s, but with
    ``fine_fallback`` and a ``hazard`` (``has_hazard``) with at least the default grid's speeds
    and headings (``FINE_SPEED_LEVELS``, ``FINE_HEADING_STEP``; a no-op with the default grid).
    Denser, not a superset: 45° headings, for one, are not on a 10° grid."""
    return Grid(*_core.grid_of(bounds, cfg, bool(hazard)))


def py_polar_grid(bounds: Bounds, cfg: Config) -> np.ndarray:
    """(M, 2) in-plane candidates: ``speed_levels`` speeds from v_min to v_max, headings every
    ``heading_step``; speed 0 once, repeated speeds once."""
    return _core.polar_grid(bounds, cfg)


def py_has_hazard(vos: VOs, nbrs: np.ndarray) -> bool:
    """Whether the decision has something that does not avoid: an obstacle's VO pyramid in
    reach or a non-cooperative neighbour (``nbrs`` column 7 is 0)."""
    return bool(_core.has_hazard(vos, nbrs))


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
    """The decision's fallbacks: ``grid_search`` (the grid's velocity nearest the preferred
    one that is within the limits, outside every VO and at least ``margin`` from every VO,
    points equally far plane by plane), and when it finds nothing ``least_bad`` (the velocity
    whose first intrusion comes latest), on one ``grid_of`` (``hazard``: see ``has_hazard``):
    (found on the grid, velocity, its plane's index or -1)."""
    return _core.fallback(vos, planes, tried, p, v_now, G3, h3, bounds, cfg, bool(hazard))


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
    """``least_bad`` on the sampled grid (``sampled``, whose candidates that grid is): among
    the tried answers (k, 3), the grid on every plane, zero and v_now, within the limits, the
    velocity whose first protected-zone intrusion comes latest (ties at once, inside zones:
    first the one closing slowest on them, with ``least_bad_escape``; then nearest the
    preferred velocity). With an acceleration limit each is also tried clipped into the
    reachable box. None within the limits: the limits' own closest point to hovering."""
    return _core.least_bad(vos, planes, tried, p, v_now, G3, h3, bounds, cfg)


# ------------------------------------------------------------------------------- Python side


def first_safe(enc: Encounter, candidates: np.ndarray) -> int | None:
    """Index of the first candidate (in the given order) that is within the limits, outside
    every VO by the exact 3D check and at least ``margin`` from every VO, or None."""
    G3, h3 = enc.linear_bounds()
    v = np.ascontiguousarray(np.asarray(candidates, dtype=float).reshape(-1, 3))
    k = _core.first_safe(enc.vos, v, G3, h3, enc.bounds, enc.options.config)
    return None if k < 0 else int(k)


def fallback(
    enc: Encounter, planes: AvoidancePlanes, tried: np.ndarray, all_failed: bool
) -> Outcome:
    """No answer passed the exact check: the fallbacks' grid (the exact check and the margin
    decide, not its sections); if none is safe either, the least-bad velocity. When the
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
