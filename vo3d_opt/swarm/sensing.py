"""Who senses whom in ``select_many``: k-d trees, never an N×N matrix (the rules: the package's
docstring). Each deciding vehicle's neighbours, static spheres and obstacles as index lists
(span, idx): row d's are ``idx[span[d, 0]:span[d, 1]]``."""

from __future__ import annotations

import math
from collections.abc import Sequence
from concurrent.futures import wait
from typing import TYPE_CHECKING, Any

import numpy as np

from ..formulations.swarm import nearest_lists, neighbor_lists
from ..types import Box, Cylinder
from .threads import _workers

if TYPE_CHECKING:  # scipy.spatial is imported by the functions that use it: it takes 0.3 s
    from scipy.spatial import cKDTree


#: The k-d trees propose candidates within range·(1 + _REACH) + _REACH, m: a hair more than the
#: range, so that a rounding difference between the tree's distance and numpy's never drops a
#: neighbour; numpy's distance then decides.
_REACH = 1e-9
_EMPTY = np.zeros(0, dtype=np.int64)


def _spans(rows: np.ndarray, cols: np.ndarray, n_rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (row, col) as index lists: ``idx[span[r, 0]:span[r, 1]]`` are row r's columns, in
    increasing order."""
    order = np.lexsort((cols, rows))
    counts = np.bincount(rows, minlength=n_rows)
    ends = np.cumsum(counts)
    span = np.stack([ends - counts, ends], axis=1).astype(np.int64)
    return span, np.ascontiguousarray(cols[order], dtype=np.int64)


def _reach(r: np.ndarray | float) -> np.ndarray | float:
    return r * (1.0 + _REACH) + _REACH


def vehicle_links(
    P: np.ndarray,
    who: np.ndarray,
    sensing_range: float,
    max_neighbors: int | None,
    threads: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Each deciding vehicle's neighbours (vehicle indices, increasing) as (span, idx): the
    vehicles within ``sensing_range`` (numpy's distance), or the ``max_neighbors`` nearest of
    them (equally near: the lower index first). ``threads``: how many may share a crowd's
    k-nearest queries (the lists are the same)."""
    n, D = P.shape[0], who.shape[0]
    if D == 0 or n < 2 or max_neighbors == 0:
        return np.zeros((D, 2), dtype=np.int64), _EMPTY
    from scipy.spatial import cKDTree

    tree = cKDTree(P)
    if max_neighbors is not None and _crowded(tree, P, who, sensing_range, max_neighbors):
        links = _nearest_links(tree, P, who, sensing_range, int(max_neighbors), threads)
        if links is not None:
            return links
    pairs = tree.query_pairs(_reach(sensing_range), output_type="ndarray")
    a, b = np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1])
    dist = np.linalg.norm(P[a] - P[b], axis=-1)
    place = np.full(n, -1, dtype=np.int64)
    place[who] = np.arange(D)
    span = np.empty((D, 2), dtype=np.int64)
    k = -1 if max_neighbors is None else int(max_neighbors)
    idx = neighbor_lists(a, b, dist, float(sensing_range), place, k, span)
    return span, idx


#: With max_neighbors = k, the tree proposes each vehicle's k + 1 + _SPARE nearest (itself among
#: them): the spare ones show whether a farther vehicle could tie with the k-th.
_SPARE = 4
#: That query replaces the list of every pair within range when the vehicles within range of
#: each vehicle (the mean of a sample, times n: twice the pairs) exceed _CROWD times
#: k + 1 + _SPARE per deciding vehicle:
#: with k = 10, the query and its ranking cost about 2.4 µs per deciding vehicle, the list of
#: every pair about 0.08 µs per vehicle and vehicle within range of it, break-even at about
#: 30 within range (1,000 vehicles, 2-core Intel Xeon VM, 2026-11-25).
_CROWD = 2
#: The query is dropped for every pair again when more than this share of the deciding vehicles
#: cannot settle their lists from its proposals (ties at the edge: a lattice), as each of those
#: then costs a query of its own.
_UNSETTLED = 0.05
#: With several threads, each ranks at least this many vehicles' proposals (fewer are not
#: worth handing over to a thread).
_PART = 256


def _norm_sums_left_to_right() -> bool:
    """Whether numpy's ``np.linalg.norm(x, axis=-1)`` of rows of three sums the squares left to
    right, as ``nearest_lists``' compiled distance does, for 1 to 4096 rows (numpy 2.4 on this
    project's x86-64 machines does; another build might not, and the lists must rank by
    numpy's distance bit for bit)."""
    x = np.random.default_rng(0).normal(size=(4096, 3)) * np.geomspace(1e-3, 1e3, 4096)[:, None]
    s = x * x
    left = np.sqrt((s[:, 0] + s[:, 1]) + s[:, 2])
    return all(
        np.array_equal(np.linalg.norm(x[:m], axis=-1), left[:m]) for m in (1, 2, 3, 7, 64, 4096)
    )


#: Whether the k-nearest query may serve (else every pair within range, ranked by numpy).
_NEAREST_OK = _norm_sums_left_to_right()


def _crowded(tree: cKDTree, P: np.ndarray, who: np.ndarray, sensing_range: float, k: int) -> bool:
    """Whether every pair within range (of all n vehicles: the tree lists them all) costs more
    than one k-nearest query per deciding vehicle, judged on 32 to 63 vehicles spread over the
    index (every (n // 32)-th: a question of speed only, both ways give the same lists)."""
    n = P.shape[0]
    if _proposed(k) >= n or not _NEAREST_OK:
        return False
    within = tree.query_ball_point(P[:: max(1, n // 32)], _reach(sensing_range), return_length=True)
    return bool(np.mean(within) * n > _CROWD * _proposed(k) * who.shape[0])


def _proposed(k: int) -> int:
    """How many nearest the tree proposes for a list of k: k + 1 + _SPARE (itself among them)."""
    return k + 1 + _SPARE


def _pair_distance(P: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """numpy's distance between vehicles i and j (broadcast): bit for bit the number the
    all-pairs path gets for the pair (a subtraction's sign flips exactly)."""
    return np.asarray(np.linalg.norm(P[i] - P[j], axis=-1))


def _ranked_within(
    tree: cKDTree, P: np.ndarray, i: int, sensing_range: float, k: int
) -> np.ndarray:
    """Vehicle i's k nearest within range among all of them (ties: the lower index)."""
    cand = np.asarray(tree.query_ball_point(P[i], _reach(sensing_range)), dtype=np.int64)
    cand = cand[cand != i]
    d = _pair_distance(P, np.array([i]), cand)
    cand, d = cand[d <= sensing_range], d[d <= sensing_range]
    return cand[np.lexsort((cand, d))[:k]]


def _nearest_links(
    tree: cKDTree, P: np.ndarray, who: np.ndarray, sensing_range: float, k: int, threads: int = 1
) -> tuple[np.ndarray, np.ndarray] | None:
    """``vehicle_links`` with max_neighbors = k from one k-nearest query of the tree: O(D k log n)
    where every pair within range costs O(pairs), the whole swarm's square in a crowd (the
    sphere swap's centre). The same lists, tie for tie: numpy's distance ranks the proposed
    vehicles (ties: the lower index; compiled, ``formulations.swarm.nearest_lists``). A vehicle
    whose proposals cannot settle its list (the farthest proposed is not clearly farther than
    its k-th nearest or the range: a tie may hide beyond) ranks all within range instead; None
    when more than _UNSETTLED of the vehicles would (a lattice, where distances tie everywhere:
    every pair is then cheaper). With ``threads`` > 1 and many vehicles, the query and the
    ranking run on that many threads, each on its share of the vehicles (both release the GIL;
    a vehicle's list does not depend on who computed it)."""
    n, D = P.shape[0], who.shape[0]
    chosen, settled = np.empty((D, k), dtype=np.int64), np.empty(D, dtype=np.bool_)

    def part(lo: int, hi: int) -> None:
        far, near = tree.query(
            P[who[lo:hi]], k=_proposed(k), distance_upper_bound=_reach(sensing_range)
        )
        settled[lo:hi] = nearest_lists(
            P, who[lo:hi], near, far, float(sensing_range), chosen[lo:hi]
        )

    parts = max(1, min(threads, D // _PART))
    cut = [D * t // parts for t in range(parts + 1)]
    helpers = [_workers(parts - 1).submit(part, cut[t], cut[t + 1]) for t in range(1, parts)]
    try:
        part(cut[0], cut[1])
    finally:  # no helper left writing into the arrays, whatever raised
        wait(helpers)
    for h in helpers:
        h.result()
    unsettled = np.flatnonzero(~settled)
    if unsettled.shape[0] > _UNSETTLED * D:
        return None
    for r in unsettled:
        pick = np.sort(_ranked_within(tree, P, int(who[r]), sensing_range, k))
        chosen[r] = n
        chosen[r, : pick.shape[0]] = pick
    count = (chosen < n).sum(axis=1)  # each list in index order, none (n) last
    ends = np.cumsum(count)
    span = np.stack([ends - count, ends], axis=1).astype(np.int64)
    return span, np.ascontiguousarray(chosen[chosen < n], dtype=np.int64)


def _all(D: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Every one of m items for each of D vehicles, as (span, idx)."""
    span = np.zeros((D, 2), dtype=np.int64)
    span[:, 1] = m
    return span, np.arange(m, dtype=np.int64)


def _near(
    tree: cKDTree | None,
    points: np.ndarray,
    centres: np.ndarray,
    bound: np.ndarray,
    surface: Any,
    rng: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(vehicle, item) pairs with item m's surface within ``rng`` of the vehicle:
    candidates from ``tree`` (over ``points``) within rng + bound[m] of centres[m], then
    ``surface(m, pts)`` decides."""
    rows, cols = [], []
    if tree is None:
        from scipy.spatial import cKDTree

        tree = cKDTree(points)
    for m, near in enumerate(tree.query_ball_point(centres, _reach(rng + bound))):
        if near:
            cand = np.asarray(near, dtype=np.int64)
            hit = cand[surface(m, points[cand]) <= rng]
            rows.append(hit)
            cols.append(np.full(hit.shape, m, dtype=np.int64))
    if not rows:
        return _EMPTY, _EMPTY
    return np.concatenate(rows), np.concatenate(cols)


def obstacle_links(
    Pd: np.ndarray,
    obstacles: Sequence[Cylinder | Box],
    obstacle_range: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The obstacles each deciding vehicle (positions ``Pd``) takes into account, as (span, idx)."""
    D, m = Pd.shape[0], len(obstacles)
    if obstacle_range is None or m == 0 or D == 0:
        return _all(D, m)
    centres = np.array([o.center for o in obstacles], dtype=float).reshape(m, 2)
    # Any point of the footprint is within this of the centre: the surface is at least
    # (horizontal distance - bound) away.
    bound = np.array(
        [o.radius if isinstance(o, Cylinder) else 0.5 * math.hypot(*o.size) for o in obstacles],
        dtype=float,
    )
    from scipy.spatial import cKDTree

    rows, cols = _near(
        cKDTree(Pd[:, :2]),
        Pd,
        centres,
        bound,
        lambda k, pts: obstacles[k].surface_distance(pts),
        obstacle_range,
    )
    return _spans(rows, cols, D)


def sphere_links(
    Pd: np.ndarray,
    spheres: np.ndarray,
    obstacle_range: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The static spheres each deciding vehicle takes into account, as (span, idx)."""
    D, s = Pd.shape[0], spheres.shape[0]
    if obstacle_range is None or s == 0 or D == 0:
        return _all(D, s)

    def surface(k: int, pts: np.ndarray) -> np.ndarray:
        return np.maximum(np.linalg.norm(pts - spheres[k, :3], axis=-1) - spheres[k, 3], 0.0)

    rows, cols = _near(None, Pd, spheres[:, :3], spheres[:, 3], surface, obstacle_range)
    return _spans(rows, cols, D)
