"""The default decision in one compiled call: plane_qp on the exact per-plane solver.

Read top to bottom, ``decide`` is the whole algorithm (formulations/plane_qp.md), the way
RVO2-3D's ``Agent.cc`` reads:

1. the VOs' inputs (``build_vos``'s parts): each neighbour's row (``cone_rows``: its position,
   the cone's apex, r_pz; the horizon, the buffer and reciprocity applied), the pyramids of
   section 4 (``pyramids_in_reach``), and the limits as rows (altitude, acceleration);
2. the preferred velocity itself, when it is within the limits and outside every VO (exact 3D
   check, on each neighbour's row: ``pref_clear``), is the optimum of every formulation:
   returned at once, before the cones' geometry, which it never needs;
3. the VO cones of eqs 1–6 with the virtual sphere (``vos_of``); the avoidance planes about the
   preferred direction (eq. 8); on each plane and in each linearisation round (near, left,
   right) one QP: the point nearest the preferred velocity inside the speed disc (or annulus),
   the altitude rows and one half-plane per VO that holds the preferred velocity or that A is
   inside (``plane_rows``: the sections of section 3.1 / 4.2 linearised), solved exactly
   (``nearest_in_disc``);
4. best first: the QP with the least deviation is checked with the exact 3D membership; a safe
   answer is the decision (every other QP's answer is at least as far: adding constraints only
   moves an answer away), an answer that enters VOs not yet constrained on that QP adds their
   rows to it and that QP is solved again (constraint generation, per QP, so an answer never
   depends on the order the QPs are solved in);
5. no QP gives a safe answer: the sampled grid with the exact check and the margin, else the
   least-bad velocity (latest first intrusion); the grid at least the default one's with an
   obstacle or a non-cooperative neighbour (``fine_fallback``);
6. the status, and the last line of the contract (never above v_max, never leaving the
   altitude band within dt).

A plane QP costs well under a microsecond, so a QP's key in the best-first order is its exact
optimum once it is the least key: before, a one-line lower bound stands in for it, and QPs that
cannot win are never solved (the Python search for outside backends, ``plane_qp.py``, uses the
exact optima as lower bounds of their answers).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._jit import entry, inline, inline_alloc, jit, kernel
from ..geometry import AvoidancePlanes
from ..solvers.exact2d import nearest_in_disc, seidel_order
from .common import (
    Bounds,
    Config,
    VOs,
    aimed,
    bounds_of,
    cone_rows,
    config_of,
    containing,
    decision_planes,
    limit_rows,
    pref_clear,
    pyramids_in_reach,
    vos_of,
    vz_range,
    within_limits,
)
from .fallback import grid_of, grid_search, has_hazard, least_bad
from .rows import ROUNDS, RowWork, plane_rows, row_work, vo_base

#: How a decision's velocity was found (``KernelOut.round``): the preferred velocity, a QP round,
#: the sampled grid, the least-bad fallback.
ROUND_NAMES = ("preferred",) + ROUNDS + ("sampled", "least_bad")
PREFERRED, SAMPLED, LEAST_BAD = 0, len(ROUNDS) + 1, len(ROUNDS) + 2
#: ``KernelOut.status`` codes: the order of vo3d_opt.status.DECISION_STATUSES.
OPTIMAL, INSIDE_PROTECTED_ZONE, INFEASIBLE_MIN_VIOLATION = 0, 1, 2


class KernelOut(NamedTuple):
    """One decision: the velocity (3,) and how it was found."""

    velocity: np.ndarray
    status: int  # index into DECISION_STATUSES
    phi: float  # the plane the velocity was chosen on (rad), NaN when none
    round: int  # index into ROUND_NAMES
    solved: int  # plane QPs solved


#: Row counts whose solver order a decision keeps (a table of KEPT_ORDERS² ints at most).
KEPT_ORDERS = 32


class PlaneQPs(NamedTuple):
    """The (round, plane) QPs of one decision and their rows, filled as VOs join.

    Rows of VO k on plane p: G[k, r, p]·w <= h[k, r, p] where active[k, p], built once a QP on
    that plane needs them (computed[k, p]) from the VO's points in the planes' frame (base[k],
    once based[k]). QP (r, p) constrains the VOs in included[r, p] plus the limit rows
    G_lim[p]·w <= h_lim and the speed disc; its exact optimum is sol[r, p] at deviation
    key[r, p] (inf: infeasible or done)."""

    G: np.ndarray  # (V, R, P, 2)
    h: np.ndarray  # (V, R, P)
    active: np.ndarray  # (V, P) bool
    computed: np.ndarray  # (V, P) bool
    base: np.ndarray  # (V, 3, K + 3)
    based: np.ndarray  # (V,) bool
    included: np.ndarray  # (R, P, V) bool
    starts: np.ndarray  # (V,) int: the VOs every QP starts with (``initial``), n_starts of them
    n_starts: int
    G_lim: np.ndarray  # (P, L, 2)
    h_lim: np.ndarray  # (L,)
    key: np.ndarray  # (R, P)
    exact: np.ndarray  # (R, P) bool: key is the QP's optimum (else a lower bound)
    complete: np.ndarray  # (P,) bool: the plane has the rows of every VO its QPs start with
    sol: np.ndarray  # (R, P, 2)
    plane_key: np.ndarray  # (P,) scratch of search: each plane's least key ...
    plane_r: np.ndarray  # (P,) int ... and the first round that has it
    w0: np.ndarray  # (2,) the preferred velocity in plane coordinates (the same on every plane)
    rows: np.ndarray  # (V + L, 2) scratch: one QP's rows ...
    rhs: np.ndarray  # (V + L,) ... their right-hand sides
    orders: np.ndarray  # (S + 1, S) the solver's row order for m <= S rows, in row m ...
    ordered: np.ndarray  # (S + 1,) bool ... once computed (S = min(V + L, KEPT_ORDERS))
    order: np.ndarray  # (V + L,) scratch: the row order of a QP of more rows
    into: np.ndarray  # (V,) scratch: the VOs a velocity is in
    todo: np.ndarray  # (V * P, 2) scratch: the (VO, plane) rows still to build
    v: np.ndarray  # (3,) scratch: a velocity
    work: RowWork  # scratch of plane_rows


@jit
def plane_qps(
    vos: VOs,
    planes: AvoidancePlanes,
    G3: np.ndarray,
    h3: np.ndarray,
    initial: np.ndarray,
    cfg: Config,
    lazy: bool,
) -> PlaneQPs:
    """The QPs of one decision, each starting with the rows of the ``initial`` VOs (those
    holding the preferred velocity, and the zones A is inside) on every plane. ``lazy``: build
    them on plane 0 only, and elsewhere only the probe's (the initial VO farthest from w0 on
    plane 0): ``search`` completes a plane when one of its QPs first comes up (a lower bound
    from the probe alone is still a lower bound, so no answer changes; planes that never come
    up are never built: the rows are most of a decision's cost)."""
    V, R, P, L = initial.shape[0], len(ROUNDS), cfg.phi.shape[0], G3.shape[0]
    G_lim = np.empty((P, L, 2))
    for p in range(P):  # the 3D limit rows G3 v <= h3 on P_phi: G3 @ [e1, e2(phi)]
        for j in range(L):
            for c in range(2):
                T = planes.to_plane[p, c]
                G_lim[p, j, c] = G3[j, 0] * T[0] + G3[j, 1] * T[1] + G3[j, 2] * T[2]
    e1 = planes.to_plane[0, 0]
    w0 = np.zeros(2)
    # v_pref lies in every plane
    w0[0] = e1[0] * vos.v_pref[0] + e1[1] * vos.v_pref[1] + e1[2] * vos.v_pref[2]
    starts, n_starts = np.empty(V, dtype=np.int64), 0
    for k in range(V):
        if initial[k]:
            starts[n_starts], n_starts = k, n_starts + 1
    included, key = np.zeros((R, P, V), dtype=np.bool_), np.empty((R, P))
    for r in range(R):
        for p in range(P):
            key[r, p] = np.inf
            for q in range(n_starts):
                included[r, p, starts[q]] = True
    qps = PlaneQPs(
        np.empty((V, R, P, 2)),
        np.empty((V, R, P)),
        np.zeros((V, P), dtype=np.bool_),
        np.zeros((V, P), dtype=np.bool_),
        np.empty((V, 3, cfg.t.shape[0] + 3)),
        np.zeros(V, dtype=np.bool_),
        included,
        starts,
        n_starts,
        G_lim,
        h3,
        key,
        np.zeros((R, P), dtype=np.bool_),
        np.ones(P, dtype=np.bool_),
        np.empty((R, P, 2)),
        np.empty(P),
        np.empty(P, dtype=np.int64),
        w0,
        np.empty((V + L, 2)),
        np.empty(V + L),
        np.empty((min(V + L, KEPT_ORDERS) + 1, min(V + L, KEPT_ORDERS)), dtype=np.int64),
        np.zeros(min(V + L, KEPT_ORDERS) + 1, dtype=np.bool_),
        np.empty(V + L, dtype=np.int64),
        np.empty(V, dtype=np.bool_),
        np.empty((V * P, 2), dtype=np.int64),
        np.empty(3),
        row_work(cfg.t.shape[0]),
    )
    # the rows of the VOs every QP starts with, on every plane (lazy: on plane 0); an int64
    # from the start, else numba compiles add_rows for the literal 0 too while it infers this
    # loop's types
    n_todo = np.int64(0)
    for k in range(V):
        for p in range((1 if lazy else P) * initial[k]):
            qps.todo[n_todo, 0], qps.todo[n_todo, 1], n_todo = k, p, n_todo + 1
    add_rows(qps, vos, planes, cfg, n_todo)
    if lazy and n_todo > 1:
        probe, far = qps.todo[0, 0], -np.inf
        for q in range(n_todo):
            k = qps.todo[q, 0]
            d = _beyond(qps, k, 0, 0) if qps.active[k, 0] else -np.inf
            if d > far:
                probe, far = k, d
        for p in range(1, P):
            qps.todo[p - 1, 0], qps.todo[p - 1, 1] = probe, p
            qps.complete[p] = False
        add_rows(qps, vos, planes, cfg, np.int64(P - 1))
    elif lazy and n_todo == 1:  # one initial VO: every plane is complete once it is built
        for p in range(1, P):
            qps.todo[p - 1, 0], qps.todo[p - 1, 1] = qps.todo[0, 0], p
        add_rows(qps, vos, planes, cfg, np.int64(P - 1))
    return qps


@kernel
def add_rows(
    qps: PlaneQPs, vos: VOs, planes: AvoidancePlanes, cfg: Config, n_todo: int | np.int64
) -> None:
    """Build the rows of the first ``n_todo`` (VO, plane) pairs of qps.todo (every round), each
    once. One call for the whole list: the arguments are large."""
    for q in range(n_todo):
        k, p = qps.todo[q, 0], qps.todo[q, 1]
        if qps.computed[k, p]:
            continue
        if not qps.based[k]:
            vo_base(vos, k, planes.frame, cfg, qps.base[k])
            qps.based[k] = True
        qps.active[k, p] = plane_rows(
            vos, k, p, qps.base[k], planes, cfg, qps.w0, qps.G[k, :, p], qps.h[k, :, p], qps.work
        )
        qps.computed[k, p] = True


@inline
def gather(qps: PlaneQPs, r: int, p: int) -> int:
    """QP (r, p)'s rows (its VOs', then the limits') into qps.rows / qps.rhs: how many."""
    m = 0
    for k in range(qps.included.shape[2]):
        if qps.included[r, p, k] and qps.active[k, p]:
            qps.rows[m, 0], qps.rows[m, 1], qps.rhs[m] = (
                qps.G[k, r, p, 0],
                qps.G[k, r, p, 1],
                qps.h[k, r, p],
            )
            m += 1
    for j in range(qps.h_lim.shape[0]):
        qps.rows[m, 0], qps.rows[m, 1], qps.rhs[m] = (
            qps.G_lim[p, j, 0],
            qps.G_lim[p, j, 1],
            qps.h_lim[j],
        )
        m += 1
    return m


@inline
def solve_qp(qps: PlaneQPs, r: int, p: int, bounds: Bounds) -> None:
    """QP (r, p) solved exactly: its optimum into sol[r, p], its deviation into key[r, p]."""
    m = gather(qps, r, p)
    out = qps.sol[r, p]
    if m >= qps.ordered.shape[0]:  # many rows: the order computed each time
        order = qps.order
        seidel_order(m, order)
    else:  # the order depends on m alone: computed once per decision
        order = qps.orders[m]
        if not qps.ordered[m]:
            seidel_order(m, order)
            qps.ordered[m] = True
    if nearest_in_disc(qps.rows, qps.rhs, m, qps.w0, bounds.v_max, bounds.v_min, order, out):
        qps.key[r, p] = np.sqrt((out[0] - qps.w0[0]) ** 2 + (out[1] - qps.w0[1]) ** 2)
    else:
        qps.key[r, p] = np.inf


@kernel
def search(
    vos: VOs,
    planes: AvoidancePlanes,
    qps: PlaneQPs,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    cfg: Config,
    tried: np.ndarray,
) -> tuple[int, int, int, int]:
    """Best-first over the QPs (step 4 of the module docstring): (round, plane) of the answer,
    or (-1, -1) when no QP gives a safe one; the QPs solved; how many answers went into
    ``tried`` (each QP answer in solve order, for the least-bad fallback).

    A QP's key starts as a cheap lower bound (the farthest of its half-planes from the
    preferred velocity) and becomes its exact optimum once it is the least key and solved, so
    QPs that can never win are not solved at all. Rows are built as QPs need them (a work list
    of (VO, plane) pairs): the VOs every QP starts with, on a plane not yet complete (see
    ``plane_qps``) when one of its QPs first has the least key, before it is solved; then those
    an answer enters, on that answer's plane."""
    R, P = qps.key.shape
    into, v, todo = qps.into, qps.v, qps.todo
    n_todo = np.int64(0)  # not the literal 0: see plane_qps
    solved = n_tried = 0
    # each plane's least key and its first round (an iteration changes the keys of its own
    # plane only: that plane's entry is refreshed at the next one)
    plane_key, plane_r, p = qps.plane_key, qps.plane_r, 0
    for it in range(
        1 + R * P * (2 + 2 * into.shape[0])
    ):  # per QP: its solve, then each VO it gains
        if n_todo > 0:  # a call passes every array of qps, vos and planes: skip it when idle
            add_rows(qps, vos, planes, cfg, n_todo)
            n_todo = np.int64(0)
        if it == 0:
            for r in range(R):
                for p in range(P):
                    qps.key[r, p], qps.exact[r, p] = _bound(qps, r, p), False
            for p in range(P):
                _least_round(qps.key, p, plane_key, plane_r)
        else:
            _least_round(qps.key, p, plane_key, plane_r)
        r, p = _argmin(plane_key, plane_r)
        if qps.key[r, p] == np.inf:
            break
        if not qps.complete[p]:  # its bound is the probe's alone: build the rest, bound again
            # (no QP on p is solved yet, so every round's included VOs are still the initial ones)
            for k in range(into.shape[0]):
                if qps.included[r, p, k] and not qps.computed[k, p]:
                    todo[n_todo, 0], todo[n_todo, 1], n_todo = k, p, n_todo + 1
            add_rows(qps, vos, planes, cfg, n_todo)
            n_todo = np.int64(0)
            for rr in range(R):
                qps.key[rr, p] = _bound(qps, rr, p)
            qps.complete[p] = True
            continue
        if not qps.exact[r, p]:
            solve_qp(qps, r, p, bounds)
            qps.exact[r, p] = True
            solved += 1
            if qps.key[r, p] < np.inf:
                lift(planes, qps.sol[r, p], p, tried[n_tried])
                n_tried += 1
            continue
        lift(planes, qps.sol[r, p], p, v)
        if not containing(vos, v, cfg.horizon, into):
            if within_limits(v, G3, h3, bounds):
                return r, p, solved, n_tried
            qps.key[r, p] = np.inf  # outside the limits within tolerance: this QP gives nothing
            continue
        new = False
        for k in range(into.shape[0]):  # constrain the VOs it entered and solve again
            if into[k] and not qps.included[r, p, k]:
                qps.included[r, p, k] = new = True
                if not qps.computed[k, p]:
                    todo[n_todo, 0], todo[n_todo, 1], n_todo = k, p, n_todo + 1
        # Solve it again (its new rows first): 0 is a valid lower bound until then.
        qps.key[r, p], qps.exact[r, p] = (0.0, False) if new else (np.inf, True)
    return -1, -1, solved, n_tried


@inline
def _bound(qps: PlaneQPs, r: int, p: int) -> float:
    """A lower bound on QP (r, p)'s deviation, before it is solved (it then constrains the VOs
    it starts with: ``starts``): its feasible set lies inside each of its half-planes (those
    built: see ``plane_qps``), so it is at least as far from w0 as the farthest of them."""
    lb = 0.0
    for q in range(qps.n_starts):
        k = qps.starts[q]
        if qps.active[k, p]:
            over = _beyond(qps, k, r, p)
            if over > 0.0:
                lb = max(lb, over)
    return lb


@inline
def _beyond(qps: PlaneQPs, k: int, r: int, p: int) -> float:
    """How far w0 lies beyond VO k's half-plane of QP (r, p) (negative: inside it)."""
    gx, gy = qps.G[k, r, p, 0], qps.G[k, r, p, 1]
    return (gx * qps.w0[0] + gy * qps.w0[1] - qps.h[k, r, p]) / np.sqrt(gx * gx + gy * gy)


@inline
def _least_round(key: np.ndarray, p: int, plane_key: np.ndarray, plane_r: np.ndarray) -> None:
    """Plane p's least key and the first round that has it, into plane_key[p], plane_r[p]."""
    br = 0
    for r in range(1, key.shape[0]):
        if key[r, p] < key[br, p]:
            br = r
    plane_key[p], plane_r[p] = key[br, p], br


@inline
def _argmin(plane_key: np.ndarray, plane_r: np.ndarray) -> tuple[int, int]:
    """The first (r, p) of the least key in (round, plane) order, from each plane's least key
    and its first round (``_least_round``): the least key, then the first round, then the
    first plane. A scan of the planes, not of every QP."""
    bp = 0
    for p in range(1, plane_key.shape[0]):
        if plane_key[p] < plane_key[bp] or (
            plane_key[p] == plane_key[bp] and plane_r[p] < plane_r[bp]
        ):
            bp = p
    return plane_r[bp], bp


@inline
def lift(planes: AvoidancePlanes, w: np.ndarray, p: int, out: np.ndarray) -> None:
    """Plane coordinates w on plane p to the world velocity out (3,)."""
    for c in range(3):
        out[c] = w[0] * planes.to_plane[p, 0, c] + w[1] * planes.to_plane[p, 1, c]


@entry
def enforce_limits(v: np.ndarray, p: np.ndarray, bounds: Bounds) -> np.ndarray:
    """The last line of the contract: never above v_max, never leaving [z_min, z_max] within dt
    (from an in-bounds start); non-finite components become 0."""
    out = np.empty(3)
    for c in range(3):
        out[c] = v[c] if np.isfinite(v[c]) else 0.0
    lo, hi = vz_range(p[2], bounds)
    out[2] = min(max(out[2], lo), hi)
    speed = np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)
    if speed > bounds.v_max:
        for c in range(3):
            out[c] *= bounds.v_max / speed
    return out


@entry
def py_plane_qps(
    vos: VOs,
    planes: AvoidancePlanes,
    G3: np.ndarray,
    h3: np.ndarray,
    initial: np.ndarray,
    cfg: Config,
    lazy: bool,
) -> PlaneQPs:
    """``plane_qps`` for Python callers (compiled code calls ``plane_qps``: no Python wrapper);
    every plane built unless ``lazy``."""
    return plane_qps(vos, planes, G3, h3, initial, cfg, lazy)


@entry
def py_search(
    vos: VOs,
    planes: AvoidancePlanes,
    qps: PlaneQPs,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: Bounds,
    cfg: Config,
    tried: np.ndarray,
) -> tuple[int, int, int, int]:
    """``search`` for Python callers (tests: lazy and complete rows give the same search)."""
    return search(vos, planes, qps, G3, h3, bounds, cfg, tried)


@entry
def py_add_rows(
    qps: PlaneQPs, vos: VOs, planes: AvoidancePlanes, cfg: Config, k: int, p: int
) -> None:
    """Build VO k's rows on plane p, for Python callers."""
    qps.todo[0, 0], qps.todo[0, 1] = k, p
    add_rows(qps, vos, planes, cfg, 1)


@entry
def py_gather(qps: PlaneQPs, r: int, p: int) -> int:
    """``gather`` for Python callers (compiled code calls ``gather``: no Python wrapper)."""
    return gather(qps, r, p)


@entry
def py_solve_qp(qps: PlaneQPs, r: int, p: int, bounds: Bounds) -> None:
    """``solve_qp`` for Python callers (compiled code calls ``solve_qp``: no Python wrapper)."""
    return solve_qp(qps, r, p, bounds)


@entry
def py_lift(planes: AvoidancePlanes, w: np.ndarray, p: int, out: np.ndarray) -> None:
    """``lift`` for Python callers (compiled code calls ``lift``: no Python wrapper)."""
    return lift(planes, w, p, out)


#: The entries of ``decide``'s output array.
OUT_SIZE = 7  # velocity (3), status, phi, round, solved


@entry
def decide(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    limits: np.ndarray,
    options: np.ndarray,
    plane_tab: np.ndarray,
    gen_tab: np.ndarray,
    out: np.ndarray,
) -> None:
    """One decision from arrays (the module docstring's steps 1–6), into ``out`` (OUT_SIZE,):
    the velocity and the fields of ``KernelOut``. ``nbrs`` (n, 8): position, velocity, r_pz,
    cooperative (1/0); ``prisms`` (m, 4): x, y, L_pz, h_pz; ``limits``: ``bounds_array``; the
    options as ``Options.packed``. Arrays in, an array out: the cheapest call from Python."""
    # Writable copies (select passes AgentState's read-only arrays): decide_one's callees are
    # then compiled once, for select_many's writable arrays too, not twice.
    res = decide_one(
        p.copy(),
        v_now.copy(),
        v_pref.copy(),
        nbrs,
        prisms,
        bounds_of(limits),
        config_of(options, plane_tab, gen_tab),
    )
    out[0], out[1], out[2] = res.velocity[0], res.velocity[1], res.velocity[2]
    out[3], out[4], out[5], out[6] = res.status, res.phi, res.round, res.solved


@inline_alloc
def decide_one(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> KernelOut:
    """``decide`` on the compiled side (``select_many`` calls it for every vehicle)."""
    pref, rows = aimed(v_pref, bounds), cone_rows(p, v_now, nbrs, bounds, cfg)  # 1
    pyramids = pyramids_in_reach(p, prisms, bounds, cfg)
    G3, h3 = limit_rows(p, v_now, nbrs, bounds, cfg)
    if pref_clear(p, rows, pyramids, pref, cfg.horizon) and within_limits(pref, G3, h3, bounds):
        return KernelOut(enforce_limits(pref, p, bounds), OPTIMAL, np.nan, PREFERRED, 0)  # 2
    vos = vos_of(p, pref, rows, pyramids, bounds, cfg)  # 3
    n, V = vos.cones.d_oi.shape[0], vos.cones.d_oi.shape[0] + vos.pyramids.L_pz.shape[0]
    initial = np.empty(V, dtype=np.bool_)
    pref_in = containing(vos, vos.v_pref, cfg.horizon, initial)
    status = OPTIMAL
    for k in range(V):  # the zones A is inside constrain every QP
        if vos.cones.inside[k] if k < n else vos.pyramids.inside[k - n]:
            initial[k], status = True, INSIDE_PROTECTED_ZONE
    # 2 on the cones kept, as the Python formulations check it: pref_clear's answer but for a
    # rounding at min_speed's margin (a bit for bit guard, not a second chance)
    if status == OPTIMAL and not pref_in and within_limits(vos.v_pref, G3, h3, bounds):
        return KernelOut(enforce_limits(vos.v_pref, p, bounds), OPTIMAL, np.nan, PREFERRED, 0)
    planes = decision_planes(vos, v_now, cfg)
    qps = plane_qps(vos, planes, G3, h3, initial, cfg, True)
    R, P = qps.key.shape
    tried = np.empty((R * P * (V + 1), 3))  # at most every QP once, then once per VO it gains
    r, plane, solved, n_tried = search(vos, planes, qps, G3, h3, bounds, cfg, tried)  # 4
    if r >= 0:
        v = np.empty(3)
        lift(planes, qps.sol[r, plane], plane, v)
        return KernelOut(enforce_limits(v, p, bounds), status, cfg.phi[plane], 1 + r, solved)
    grid = grid_of(bounds, cfg, has_hazard(vos, nbrs))  # 5 (fine_fallback: see Options)
    cover = np.empty((P, grid.discs.shape[0]), dtype=np.int64)  # the cones holding its blocks
    found, v, plane = grid_search(vos, planes, grid, G3, h3, bounds, cfg, cover)
    if found:
        return KernelOut(enforce_limits(v, p, bounds), status, cfg.phi[plane], SAMPLED, solved)
    v = least_bad(vos, planes, grid, cover, tried[:n_tried], p, v_now, G3, h3, bounds, cfg)
    return KernelOut(  # 6
        enforce_limits(v, p, bounds), INFEASIBLE_MIN_VIOLATION, np.nan, LEAST_BAD, solved
    )
