"""plane_qp on an outside backend (formulations/plane_qp.md).

The default backend, ``exact2d``, runs the whole decision compiled (``kernel.decide``). Every
other QP backend gets the same QPs, built from the same rows (``kernel.PlaneQPs``), searched the
same way: best first, with constraint generation per QP. Here each QP's exact optimum over the
speed disc (``PlaneQPs.solve``) serves as its lower bound: the backend's answer is at least as
far from the preferred velocity (its speed bound is the disc itself or a polygon inside it), so
once the best safe answer beats every remaining bound the search is over, and it returns what
solving every QP to its fixpoint would. The bound also proves infeasible QPs infeasible without
a backend call."""

from __future__ import annotations

import functools
import math

import numpy as np

from ..solvers import QP
from ..status import Status
from .common import Encounter, Outcome, Solve, py_decision_planes
from .fallback import fallback
from .kernel import py_plane_qps
from .rows import ROUNDS

#: Bounds within this much (m/s) of the best deviation found cannot improve on it meaningfully.
_TIE = 1e-6

#: The plane QPs' Hessian: the objective is ||w - w0||² (read-only, shared).
_HESSIAN = 2.0 * np.eye(2)
_HESSIAN.setflags(write=False)


@functools.lru_cache(maxsize=32)
def speed_polygon(radius: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular polygon inscribed in the disc |w| <= radius, as G w <= h (read-only arrays)."""
    ang = (np.arange(sides) + 0.5) * 2 * np.pi / sides
    G, h = (
        np.stack([np.cos(ang), np.sin(ang)], axis=-1),
        np.full(sides, radius * np.cos(np.pi / sides)),
    )
    G.setflags(write=False)
    h.setflags(write=False)
    return G, h


def select_plane_qp(enc: Encounter, solve: Solve, has_cones: bool) -> Outcome:
    """The best safe answer over the (round, plane) QPs on the backend ``solve``."""
    cfg, bounds = enc.options.config, enc.bounds
    planes = py_decision_planes(enc.vos, enc.v_now, cfg)
    G3, h3 = enc.qp_bounds()
    qps = py_plane_qps(enc.vos, planes, G3, h3, enc.pref_in | enc.inside, cfg, False)
    key, included = qps.key, qps.included  # views of the compiled state, fixed in size
    P = key.shape[1]
    qps.solve_all(bounds)  # each QP's exact optimum: a lower bound of the backend's
    G_speed, h_speed = (
        (np.zeros((0, 2)), np.zeros(0))
        if has_cones
        else speed_polygon(enc.limits.v_max, enc.options.polygon_sides)
    )
    q = -2.0 * qps.w0  # ||w - w0||² = wᵀw - 2 w0ᵀw + const
    w0 = qps.w0.tolist()
    best, best_dev, tried, failed, attempts = None, math.inf, [], 0, 0
    solved: set[tuple[int, bytes, bytes]] = set()
    v, entered = np.empty(3), np.empty(included.shape[2], dtype=bool)
    while True:
        r, p = divmod(int(np.argmin(key)), P)
        if not key[r, p] < best_dev - _TIE:  # no remaining QP can beat the best answer
            break
        m = qps.gather(r, p)
        G, h = np.concatenate((qps.rows[:m], G_speed)), np.concatenate((qps.rhs[:m], h_speed))
        key[r, p] = math.inf  # done, unless its answer brings new constraints
        if (done := (p, G.tobytes(), h.tobytes())) in solved:
            continue
        solved.add(done)
        res = solve(
            QP(P=_HESSIAN, q=q, G=G, h=h, soc_radius=enc.limits.v_max if has_cones else None)
        )
        attempts += 1
        if not (res.ok and res.x is not None and res.x.shape == (2,)):
            failed += res.status == Status.FAILED
            continue
        qps.lift(res.x, p, v)
        tried.append(v.copy())
        x, y = res.x.tolist()
        dev = math.hypot(x - w0[0], y - w0[1])  # |v - v_pref|: planes are isometric
        if dev >= best_dev:  # more constraints only move it farther
            continue
        if not qps.entered(v, entered):
            if qps.within(v, bounds):
                best, best_dev = (v.copy(), p, ROUNDS[r]), dev
        elif not np.all(included[r, p][entered]):  # constrain the VOs it entered, solve again
            for j in np.flatnonzero(entered):
                qps.add_rows(int(j), p)
            included[r, p] |= entered
            qps.solve(r, p, bounds)
    if best is not None:
        v, p, mode = best
        return Outcome(v, Status.OPTIMAL, float(planes.phi[p]), {"round": mode, "solved": attempts})
    return fallback(
        enc, planes, np.array(tried).reshape(-1, 3), all_failed=attempts > 0 and failed == attempts
    )
