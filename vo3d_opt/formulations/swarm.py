"""``select_many``'s compiled side: every deciding vehicle of a swarm in one call.

The Python side (``vo3d_opt.swarm``) finds who senses whom with a k-d tree and hands the answer
over as index lists (a vehicle's neighbours are ``nb_idx[nb_span[d, 0]:nb_span[d, 1]]``, the
same for the static spheres and the obstacles). Here, in one loop over the deciding
vehicles, each vehicle's ``nbrs`` and ``prisms`` rows are built from those lists and
``kernel.decide_one`` decides for it: exactly what ``select`` computes for that vehicle, with
no Python object per vehicle or neighbour.

``neighbor_lists`` turns the k-d tree's pairs into those lists (a counting sort by vehicle),
``nearest_lists`` ranks the tree's k-nearest proposals in a crowd; they live here, beside
``decide_range``, so that ``vo3d compile`` (formulations/aot.py) puts them in its module and a
first ``select_many`` compiles nothing.

Parallel over vehicles: ``decide_range`` is compiled ``nogil`` and ``vo3d_opt.swarm.decide_all``
runs ranges of vehicles on several threads at once. Not numba's ``prange``: a ``parallel=True``
kernel compiles the whole decision kernel's code twice more (the parfor body and its caller
are separate LLVM modules, each linking and generating machine code for everything
``decide_one`` calls), measured 14 s against 4.4 s for this one on the 2-core machine. The
vehicles are independent, so the answers do not depend on the number of threads.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._jit import entry, inline, inline_alloc
from .common import bounds_of, config_of
from .kernel import OUT_SIZE, decide_one

#: Columns of ``Swarm.agents``: position (3), velocity (3), preferred velocity (3), r_pz,
#: cooperative (1: it decides, 0: it keeps its velocity whatever the others do).
AGENT_COLUMNS = 11
#: ``decide_range``'s output row: ``kernel.decide``'s (velocity, status, phi, round, solved),
#: then the vehicles and the static zones (spheres and obstacles) the vehicle took into account.
MANY_OUT_SIZE = OUT_SIZE + 2


class Swarm(NamedTuple):
    """One ``select_many`` call as arrays. Vehicle rows i < N, deciding vehicles d < D."""

    agents: np.ndarray  # (N, AGENT_COLUMNS) float
    limits: np.ndarray  # (N, 6) ``bounds_array`` of each vehicle
    who: np.ndarray  # (D,) int64: the vehicle index of each deciding vehicle
    nb_span: np.ndarray  # (D, 2) int64: its neighbours are nb_idx[lo:hi] (vehicle indices)
    nb_idx: np.ndarray  # (E,) int64
    spheres: np.ndarray  # (S, 4): x, y, z, r_pz of static spheres (zero-velocity neighbours)
    sp_span: np.ndarray  # (D, 2) int64 into sp_idx
    sp_idx: np.ndarray  # (F,) int64
    prisms: np.ndarray  # (M, 4): ``prism_rows`` of the obstacles
    ob_span: np.ndarray  # (D, 2) int64 into ob_idx
    ob_idx: np.ndarray  # (G,) int64


#: (dtype, dimensions) of each field of ``Swarm``, all C-contiguous (``SwarmInputs.arrays``
#: builds them so): the type the ahead-of-time kernel is compiled for (formulations/aot.py).
SWARM_FIELDS = (
    (np.float64, 2),
    (np.float64, 2),
    (np.int64, 1),
    (np.int64, 2),
    (np.int64, 1),
    (np.float64, 2),
    (np.int64, 2),
    (np.int64, 1),
    (np.float64, 2),
    (np.int64, 2),
    (np.int64, 1),
)


@inline_alloc
def vehicle_rows(sw: Swarm, d: int) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle who[d]'s ``nbrs`` (its neighbours, each with r_pz = max(own, theirs), then the
    spheres: zero velocity, their own r_pz, not cooperative) and ``prisms``, as ``select``
    builds them from ``Neighbor`` and obstacle objects."""
    i, a = sw.who[d], sw.agents
    lo, hi = sw.nb_span[d, 0], sw.nb_span[d, 1]
    slo, shi = sw.sp_span[d, 0], sw.sp_span[d, 1]
    nbrs = np.empty((hi - lo + shi - slo, 8))
    for e in range(lo, hi):
        j, row = sw.nb_idx[e], e - lo
        for c in range(6):
            nbrs[row, c] = a[j, c]
        nbrs[row, 6] = max(a[i, 9], a[j, 9])
        nbrs[row, 7] = a[j, 10]
    for e in range(slo, shi):
        s, row = sw.sp_idx[e], hi - lo + e - slo
        for c in range(3):
            nbrs[row, c] = sw.spheres[s, c]
            nbrs[row, 3 + c] = 0.0
        nbrs[row, 6] = sw.spheres[s, 3]
        nbrs[row, 7] = 0.0
    olo, ohi = sw.ob_span[d, 0], sw.ob_span[d, 1]
    prisms = np.empty((ohi - olo, 4))
    for e in range(olo, ohi):
        for c in range(4):
            prisms[e - olo, c] = sw.prisms[sw.ob_idx[e], c]
    return nbrs, prisms


@inline_alloc
def decide_vehicle(
    sw: Swarm,
    d: int,
    options: np.ndarray,
    plane_tab: np.ndarray,
    gen_tab: np.ndarray,
    out: np.ndarray,
) -> None:
    """``kernel.decide`` for vehicle who[d], into ``out`` (MANY_OUT_SIZE,)."""
    cfg = config_of(options, plane_tab, gen_tab)  # views, no copies: cheap per vehicle
    i, a = sw.who[d], sw.agents
    # C-contiguous, as decide_one is compiled for
    p, v_now, v_pref = np.empty(3), np.empty(3), np.empty(3)
    for c in range(3):
        p[c], v_now[c], v_pref[c] = a[i, c], a[i, 3 + c], a[i, 6 + c]
    nbrs, prisms = vehicle_rows(sw, d)
    res = decide_one(p, v_now, v_pref, nbrs, prisms, bounds_of(sw.limits[i]), cfg)
    out[0], out[1], out[2] = res.velocity[0], res.velocity[1], res.velocity[2]
    out[3], out[4], out[5], out[6] = res.status, res.phi, res.round, res.solved
    out[7] = sw.nb_span[d, 1] - sw.nb_span[d, 0]
    out[8] = sw.sp_span[d, 1] - sw.sp_span[d, 0] + sw.ob_span[d, 1] - sw.ob_span[d, 0]


@entry
def decide_range(
    sw: Swarm,
    lo: int,
    hi: int,
    options: np.ndarray,
    plane_tab: np.ndarray,
    gen_tab: np.ndarray,
    out: np.ndarray,
) -> None:
    """Deciding vehicles lo <= d < hi of ``sw``: row d of ``out`` (D, MANY_OUT_SIZE) for vehicle
    who[d]. The options as ``Options.packed``. Compiled ``nogil``: ``vo3d_opt.swarm`` runs
    several ranges at once on threads."""
    for d in range(lo, hi):
        decide_vehicle(sw, d, options, plane_tab, gen_tab, out[d])


#: Neighbour lists up to this long are sorted in place (insertion sort), longer ones by numpy.
_SMALL_ROW = 48


@inline
def _insertion(key_i: np.ndarray, key_d: np.ndarray, c: int, by_distance: bool) -> None:
    """Stable insertion sort of the first c entries of (key_i, key_d) by key_d (``by_distance``)
    or by key_i."""
    for q in range(1, c):
        i, d = key_i[q], key_d[q]
        r = q
        while r > 0 and ((key_d[r - 1] > d) if by_distance else (key_i[r - 1] > i)):
            key_i[r], key_d[r] = key_i[r - 1], key_d[r - 1]
            r -= 1
        key_i[r], key_d[r] = i, d


@entry
def neighbor_lists(
    a: np.ndarray,
    b: np.ndarray,
    dist: np.ndarray,
    sensing_range: float,
    place: np.ndarray,
    k: int,
    span: np.ndarray,
) -> np.ndarray:
    """The pairs (a[e], b[e]) at distance dist[e] as each deciding vehicle's neighbour list
    (``place``: a vehicle's row, -1 when it does not decide): those within ``sensing_range``,
    the k nearest of them when k >= 0 (ties: the lower index), in increasing index order, into
    ``span`` (D, 2); returns the concatenated lists. A counting sort by row: O(pairs)."""
    D = span.shape[0]
    count = np.zeros(D + 1, dtype=np.int64)
    for e in range(a.shape[0]):
        if dist[e] <= sensing_range:
            if place[a[e]] >= 0:
                count[place[a[e]] + 1] += 1
            if place[b[e]] >= 0:
                count[place[b[e]] + 1] += 1
    start = np.cumsum(count)
    fill = start.copy()
    idx, near = np.empty(start[D], dtype=np.int64), np.empty(start[D])
    for e in range(a.shape[0]):
        if dist[e] <= sensing_range:
            for x, y in ((a[e], b[e]), (b[e], a[e])):
                r = place[x]
                if r >= 0:
                    idx[fill[r]], near[fill[r]] = y, dist[e]
                    fill[r] += 1
    out, m = np.empty(start[D], dtype=np.int64), 0
    widest = 0
    for r in range(D):
        widest = max(widest, start[r + 1] - start[r])
    key_i, key_d = np.empty(widest, dtype=np.int64), np.empty(widest)
    for r in range(D):
        c = start[r + 1] - start[r]
        if c > _SMALL_ROW:  # a crowd: sorting with allocations is cheaper than insertion
            # Every sort a stable merge sort (one compiled sort, not three: numba's quicksort
            # and np.sort each compile for seconds); a row's indices are distinct, so sorting
            # them by any method gives the same order.
            row, d = idx[start[r] : start[r + 1]], near[start[r] : start[r + 1]]
            by_index = np.argsort(row, kind="mergesort")
            row, d = row[by_index], d[by_index]
            if 0 <= k < c:
                row = row[np.argsort(d, kind="mergesort")[:k]]  # stable: ties by index
                row = row[np.argsort(row, kind="mergesort")]
            c = row.shape[0]
            for q in range(c):  # a loop, not a slice assignment: no shape check to compile
                out[m + q] = row[q]
        else:
            for q in range(c):  # by index, then (stable) by distance: ties keep the lower index
                key_i[q], key_d[q] = idx[start[r] + q], near[start[r] + q]
            _insertion(key_i, key_d, c, False)
            if 0 <= k < c:
                _insertion(key_i, key_d, c, True)
                c = k
                _insertion(key_i, key_d, c, False)
            for q in range(c):
                out[m + q] = key_i[q]
        span[r, 0] = m
        m += c
        span[r, 1] = m
    return out[:m].copy()


@inline
def _distance(P: np.ndarray, i: int, j: int) -> float:
    """numpy's ``np.linalg.norm(P[i] - P[j])``: its squares summed left to right, as numpy's
    reduction over a row of three does (``vo3d_opt.swarm`` checks that at import and keeps
    numpy's own norm where it does not)."""
    d0, d1, d2 = P[i, 0] - P[j, 0], P[i, 1] - P[j, 1], P[i, 2] - P[j, 2]
    return np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)


@entry
def nearest_lists(
    P: np.ndarray,
    who: np.ndarray,
    near: np.ndarray,
    far: np.ndarray,
    sensing_range: float,
    chosen: np.ndarray,
) -> np.ndarray:
    """Each deciding vehicle's k nearest within ``sensing_range`` (ties: the lower index) from
    the k-d tree's proposals (its K nearest: ``near`` (D, K) indices, n for none, ``far`` (D, K)
    the tree's distances), ranked by numpy's distance, into ``chosen`` (D, k) in increasing
    index order (n for none). Returns whether each list is settled: whether every vehicle the
    tree did not propose lies clearly beyond the k-th nearest (or the range), so that no tie
    hides beyond the proposals (``vo3d_opt.swarm._nearest_links`` ranks the others anew)."""
    n, (D, K), k = P.shape[0], near.shape, chosen.shape[1]
    settled = np.empty(D, dtype=np.bool_)
    key_i, key_d = np.empty(K, dtype=np.int64), np.empty(K)
    for r in range(D):
        i = who[r]
        for q in range(K):  # a vehicle out of range or none: (inf, n), after every real one
            j = near[r, q]
            key_i[q], key_d[q] = n, np.inf
            if j < n and j != i:
                d = _distance(P, i, j)
                if d <= sensing_range:
                    key_i[q], key_d[q] = j, d
        _insertion(key_i, key_d, K, False)  # by index, then (stable) by distance
        _insertion(key_i, key_d, K, True)
        edge = min(key_d[k - 1], sensing_range)
        settled[r] = np.isinf(far[r, K - 1]) or far[r, K - 1] > edge * (1.0 + 1e-9) + 1e-12
        _insertion(key_i, key_d, k, False)  # the k nearest in index order, none (n) last
        for q in range(k):
            chosen[r, q] = key_i[q]
    return settled
