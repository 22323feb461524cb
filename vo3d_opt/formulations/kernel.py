"""The default decision in one compiled call: plane_qp on the exact per-plane solver.

The algorithm is compiled (``vo3d_opt._core``) and reads top to bottom in
``vo3d_opt/algorithm/decide.hpp`` (formulations/plane_qp.md), the way RVO2-3D's ``Agent.cc``
reads: the VOs' inputs and the limits as rows; the preferred velocity itself when it is safe;
the VO cones and pyramids, the avoidance planes about the preferred direction and, on each
plane and in each linearisation round, one QP solved exactly; a best-first search over those
QPs with constraint generation and the exact 3D check; the fallbacks' grid and the least-bad
velocity when no QP gives a safe answer; the limits, whatever came before.

Here: the names of its answer's fields, the entries ``decide`` and ``object_path`` (select()
in one call), and the plane QPs for the Python search on outside backends (``plane_qp.py``:
``PlaneQPs``, whose arrays are numpy views of the compiled state).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

import vo3d_opt._core as _core

from ..geometry import AvoidancePlanes
from ..status import DECISION_STATUSES
from ..types import MAX_MAGNITUDE, AgentState, Box, Cylinder, Limits, Neighbor
from .common import Bounds, Config, VOs
from .inputs import DEFAULT_LIMITS
from .rows import ROUNDS

#: How a decision's velocity was found (``info["round"]``): the preferred velocity, a QP round,
#: a point of the fallbacks' grid ("sampled"), the least-bad fallback.
ROUND_NAMES = ("preferred",) + ROUNDS + ("sampled", "least_bad")
PREFERRED, SAMPLED, LEAST_BAD = 0, len(ROUNDS) + 1, len(ROUNDS) + 2
#: ``decide``'s status codes: the order of vo3d_opt.status.DECISION_STATUSES.
OPTIMAL, INSIDE_PROTECTED_ZONE, INFEASIBLE_MIN_VIOLATION = 0, 1, 2
#: The entries of ``decide``'s output array: velocity (3), status, phi, round, solved.
OUT_SIZE: int = _core.OUT_SIZE
OUT_STATUS, OUT_PHI, OUT_ROUND, OUT_SOLVED = 3, 4, 5, 6
#: The statuses and the rounds by their codes in ``decide``'s output (floats there).
_STATUS_OF = {float(code): status for code, status in enumerate(DECISION_STATUSES)}
_ROUND_OF = {float(code): name for code, name in enumerate(ROUND_NAMES)}

#: One decision from arrays into ``out`` (OUT_SIZE,): ``decide(p, v_now, v_pref, nbrs, prisms,
#: limits, cfg, out)``; ``nbrs`` (n, 8): position, velocity, r_pz, cooperative (1/0);
#: ``prisms`` (m, 6) ``prism_rows`` (or (m, 4): no roofs); ``limits``: ``bounds_array``;
#: ``cfg``: ``Options.config``.
#: Arrays of another dtype or shape raise ValueError naming the argument.
decide = _core.decide
#: ``decide`` from the rows as ``select`` holds them (``formulations.inputs``): the preferred
#: velocity a tuple of 3 numbers (or an array), ``nbrs`` a list of ``Neighbor.row`` (or an (n, 8)
#: array), ``prisms`` a list of obstacles' ``prism`` (or an (m, 6) or (m, 4) array), ``limits``
#: ``inputs.bounds_row``. The same numbers give the same answer as ``decide``; a row of another
#: length raises ValueError naming it.
decide_rows = _core.decide_rows

#: The (round, plane) QPs of one decision and their rows, filled as VOs join:
#: ``PlaneQPs(vos, planes, G3, h3, initial, cfg, lazy)``, each QP starting with the rows of the
#: ``initial`` VOs (those holding the preferred velocity, and the zones A is inside) on every
#: plane (``lazy``: on plane 0, the rest as the search needs them). QP (r, p) constrains the VOs
#: in ``included[r, p]``, the limit rows G3 v <= h3 and the speed disc; ``solve(r, p, bounds)``
#: puts its exact optimum in ``sol[r, p]`` and its deviation in ``key[r, p]`` (inf:
#: infeasible); ``gather(r, p)`` its rows into ``rows`` / ``rhs`` (how many); ``add_rows(k, p)``
#: builds VO k's rows on plane p; ``search(bounds, tried)`` is the compiled best-first search.
PlaneQPs = _core.PlaneQPs


def answer(
    out: np.ndarray, t0: float, decision: type, selector: Any, clock: Callable[[], float]
) -> Any:
    """select()'s ``decision`` of ``decide``'s output ``out`` (``OUT_SIZE``), for ``selector``
    (its formulation and solver), its solve time ``clock() - t0``."""
    values = out.tolist()
    phi = values[OUT_PHI]
    return decision(  # by position: a keyword each costs a decision 40 ns
        out[:3].copy(),  # an array of its own, as the one-call path gives
        _STATUS_OF[values[OUT_STATUS]],
        clock() - t0,
        selector.formulation,
        selector.solver,
        None if phi != phi else phi,  # NaN: no plane
        {"round": _ROUND_OF[values[OUT_ROUND]], "solved": int(values[OUT_SOLVED])},
    )


def object_path(
    decision: type, selector: Any, clock: Callable[[], float]
) -> _core.ObjectPath | None:
    """``selector.select()`` on the default path in one compiled call (algorithm/objects.hpp):
    ``decide(own, preferred_velocity, neighbors, obstacles, limits, dt, t0)`` reads the
    ``AgentState``, ``Neighbor``, ``Cylinder`` and ``Box`` objects where they lie (the
    neighbours' fields, the obstacles' cached prisms), decides, and builds ``decision`` as
    select() does (``clock() - t0`` its solve time); it returns None for inputs of any other
    kind, which then take select()'s own checks. ``decide_arrays`` is the same for
    ``select_arrays``. The limits and the period are planned with
    ``selector._bounds_and_config``'s bounds and Config. No path (None) under a numpy whose
    array struct the core was not written for.
    """
    if int(np.__version__.split(".")[0]) not in (1, 2):
        return None  # the array struct the core reads is numpy 1's and 2's; others: Python
    kinds = dict(agent=AgentState, neighbor=Neighbor, cylinder=Cylinder, box=Box, limits=Limits)
    return _core.ObjectPath(
        dict(
            **kinds,
            decision=decision,
            ndarray=np.ndarray,
            empty=np.empty,
            default_limits=DEFAULT_LIMITS,
            statuses=DECISION_STATUSES,
            rounds=ROUND_NAMES,
            formulation=selector.formulation,
            solver=selector.solver,
            clock=clock,
            bounds_and_config=selector._bounds_and_config,
            max_magnitude=MAX_MAGNITUDE,
        )
    )


def py_plane_qps(
    vos: VOs,
    planes: AvoidancePlanes,
    G3: np.ndarray,
    h3: np.ndarray,
    initial: np.ndarray,
    cfg: Config,
    lazy: bool,
) -> _core.PlaneQPs:
    """The plane QPs of one decision (every plane built unless ``lazy``)."""
    return PlaneQPs(vos, planes, G3, h3, initial, cfg, lazy)


def py_search(qps: _core.PlaneQPs, bounds: Bounds, tried: np.ndarray) -> tuple[int, int, int, int]:
    """The best-first search over ``qps``: (round, plane) of the answer, or (-1, -1) when no QP
    gives a safe one; the QPs solved; how many answers went into ``tried`` (each QP answer in
    solve order, (3 P (V + 1), 3) at least)."""
    return qps.search(bounds, tried)


def enforce_limits(v: np.ndarray, p: np.ndarray, bounds: Bounds) -> np.ndarray:
    """The limits, whatever came before: never above v_max, never leaving [z_min, z_max] within dt
    and, with an acceleration limit, keeping room to brake before either (``vz_range``; from an
    in-bounds start); non-finite components become 0."""
    return _core.enforce_limits(v, p, bounds)


def py_lift(planes: AvoidancePlanes, w: np.ndarray, p: int, out: np.ndarray) -> None:
    """Plane coordinates w on plane p to the world velocity ``out`` (3,)."""
    _core.lift(planes, w, p, out)
