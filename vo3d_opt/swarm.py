"""The Python side of ``VelocitySelector.select_many``: the arrays checked, who
senses whom (k-d trees, never an N×N matrix), and the answer, ``SwarmDecision``.

Sensing, for deciding vehicle i (the same rules as a loop of ``select`` calls would apply):

* vehicles: every other vehicle j whose centre distance ``‖P[i] − P[j]‖`` is at most
  ``sensing_range`` (or, with ``max_neighbors = k``, the k nearest of them), in index order, each
  seen with ``r_pz = max(R[i], R[j])``, its current velocity, and as cooperative when it decides
  too. scipy's ``cKDTree`` proposes the candidates within a hair more than the range (with
  ``max_neighbors``, each vehicle's few nearest: a crowd does not cost the square of its size);
  the range and the ranking are then numpy's distance, so the neighbour sets are exactly those
  of a brute-force ``np.linalg.norm`` test;
* obstacles: all of them, in the order given (the same for every vehicle); with
  the ``obstacle_range`` extension only those whose surface is within that distance
  (``Cylinder.surface_distance`` / ``Box.surface_distance``), found through a 2D k-d tree over
  the vehicles so that many obstacles stay cheap;
* static spheres (the ``spheres`` extension, (S, 5): x, y, z, radius, r_pz): zero-velocity,
  non-cooperative neighbours with their own r_pz after the vehicles, filtered like the obstacles
  (surface distance ``max(‖p − c‖ − radius, 0)``).
"""

from __future__ import annotations

import math
import numbers
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .formulations.common import bounds_array
from .formulations.swarm import (
    AGENT_COLUMNS,
    Swarm,
    nearest_lists,
    neighbor_lists,
)
from .geometry.pyramid import prism_rows
from .types import MAX_MAGNITUDE, Box, Cylinder, Limits, positive_seconds, short_repr

if TYPE_CHECKING:  # scipy.spatial is imported by the functions that use it: it takes 0.3 s
    from scipy.spatial import cKDTree


#: The k-d trees propose candidates within range·(1 + _REACH) + _REACH, m: a hair more than the
#: range, so that a rounding difference between the tree's distance and numpy's never drops a
#: neighbour; numpy's distance then decides.
_REACH = 1e-9
_EMPTY = np.zeros(0, dtype=np.int64)


@dataclass
class SwarmDecision:
    """What ``select_many`` returns, per vehicle in the order given.

    ``velocities`` (N, 3) m/s: the decision, or the current velocity of a vehicle that does not
    decide; ``statuses`` (N,) str: the status of ``select``, "" for a vehicle that does not
    decide; ``solve_time`` s: the whole call. Also: ``decided`` (N,) bool;
    ``rounds`` (N,) str: how each velocity was found (``Decision.info["round"]``: "preferred", a
    QP round, "sampled", "least_bad"); ``planes`` (N,) rad: the avoidance plane chosen (NaN: none);
    ``neighbors`` (N,) int: the vehicles each took into account; ``obstacles`` (N,) int: the
    obstacles and spheres it took into account; ``solved`` (N,) int: plane QPs solved; ``times``
    (N,) s: each vehicle's share of the time (its own ``select`` call when looping, the call's
    time shared equally among the deciding vehicles when compiled; NaN when not deciding);
    ``compiled``: whether the one compiled call ran (else a loop of ``select``); ``threads``:
    threads used."""

    velocities: np.ndarray
    statuses: np.ndarray
    solve_time: float
    decided: np.ndarray
    rounds: np.ndarray
    planes: np.ndarray
    neighbors: np.ndarray
    obstacles: np.ndarray
    solved: np.ndarray
    times: np.ndarray
    compiled: bool = False
    threads: int = 1
    info: dict[str, Any] = field(default_factory=dict)


# ------------------------------------------------------------------------------ the arrays


def _real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _array(value: Any, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A finite float array of exactly ``shape`` (C-contiguous, a copy), or ValueError: real
    numbers only (as ``select`` takes them: no booleans, strings or complex numbers), each at
    most ``MAX_MAGNITUDE``."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        raw = np.asarray(None)
    if raw.dtype.kind not in "iuf":
        if raw.dtype.kind == "O" and raw.size and all(_real(x) for x in raw.ravel().tolist()):
            raw = _objects_as_floats(raw, name)
        else:
            raise ValueError(
                f"{name}: expected real numbers of shape {shape}, got {_kind_of(value, raw)}"
            )
    if raw.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {raw.shape}")
    arr = np.array(raw, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite (no NaN or inf)")
    if np.any(np.abs(arr) > MAX_MAGNITUDE):
        raise ValueError(f"{name}: must be at most {MAX_MAGNITUDE:g} in magnitude")
    return np.ascontiguousarray(arr)


def _objects_as_floats(raw: np.ndarray, name: str) -> np.ndarray:
    """An object array of Python numbers (ints beyond int64 among them) as floats."""
    try:
        return raw.astype(float)
    except OverflowError:
        raise ValueError(f"{name}: must be at most {MAX_MAGNITUDE:g} in magnitude") from None


def _kind_of(value: Any, raw: np.ndarray) -> str:
    kinds = {"b": "booleans", "c": "complex numbers", "U": "text", "S": "bytes", "O": "objects"}
    return kinds.get(raw.dtype.kind, type(value).__name__)


def points(value: Any, name: str, n: int | None = None) -> np.ndarray:
    """(n, 3) finite floats; ``n`` None: any number of rows."""
    if n is None:
        shape = np.shape(value)
        if len(shape) != 2 or shape[1] != 3:
            raise ValueError(f"{name}: expected shape (N, 3), got {shape}")
        n = shape[0]
    return _array(value, name, (n, 3))


def radii(value: Any, name: str, n: int) -> np.ndarray:
    """(n,) positive finite floats from one number or n of them."""
    if _real(value):
        value = np.full(n, float(value))
    arr = _array(value, name, (n,))
    if np.any(arr <= 0):
        raise ValueError(f"{name}: must be positive")
    return arr


def mask(value: Any, name: str, n: int) -> np.ndarray:
    """(n,) bool from None (all true) or n booleans (or 0/1)."""
    if value is None:
        return np.ones(n, dtype=bool)
    arr = np.asarray(value)
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {arr.shape}")
    if arr.dtype != bool:
        if not (np.issubdtype(arr.dtype, np.number) and np.all((arr == 0) | (arr == 1))):
            raise ValueError(f"{name}: expected booleans (or 0/1)")
        arr = arr != 0
    return arr.copy()


def distance(value: Any, name: str, *, allow_inf: bool = False) -> float:
    """A positive distance in m (inf allowed when ``allow_inf``; a finite one at most
    ``MAX_MAGNITUDE``)."""
    try:
        metres = float(value) if _real(value) else math.nan
    except OverflowError:  # an int beyond a float's range: as far as any
        metres = math.inf
    if math.isinf(metres) and allow_inf and metres > 0:
        return metres
    if not (math.isfinite(metres) and 0 < metres <= MAX_MAGNITUDE):
        what = "positive" if allow_inf else "positive finite"
        raise ValueError(
            f"{name}: must be a {what} number of metres (at most {MAX_MAGNITUDE:g} when "
            f"finite), got {short_repr(value)}"
        )
    return metres


#: A count beyond this is as good as "all" (no swarm has more vehicles).
COUNT_MAX = 10**9


def count(value: Any, name: str) -> int | None:
    """None or an integer >= 0 (beyond ``COUNT_MAX``: ``COUNT_MAX``, which means all)."""
    if value is None:
        return None
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)) or value < 0:
        raise ValueError(f"{name}: must be None or an integer >= 0, got {short_repr(value)}")
    return min(int(value), COUNT_MAX)


def vehicle_limits(limits: Limits, dt: float, n: int, max_speed: Any) -> np.ndarray:
    """(n, 6) ``bounds_array`` rows; the ``max_speed`` extension (one number or (n,), m/s) caps
    each vehicle's v_max (a scenario's per-agent ``max_speed``)."""
    rows = np.tile(bounds_array(limits, dt), (n, 1))
    if max_speed is not None:
        cap = radii(max_speed, "max_speed", n)
        if np.any(cap < limits.v_min):
            raise ValueError(f"max_speed: below the minimum speed {limits.v_min:g}")
        rows[:, 1] = np.minimum(rows[:, 1], cap)
    return rows


def sphere_rows(value: Any) -> np.ndarray:
    """The ``spheres`` extension: (S, 5) x, y, z, radius, r_pz (radius >= 0, r_pz > 0)."""
    if value is None:
        return np.zeros((0, 5))
    shape = np.shape(value)
    if len(shape) != 2 or shape[1] != 5:
        raise ValueError(f"spheres: expected shape (S, 5) (x, y, z, radius, r_pz), got {shape}")
    arr = _array(value, "spheres", shape)
    if np.any(arr[:, 3] < 0) or np.any(arr[:, 4] <= 0):
        raise ValueError("spheres: radius must be >= 0 and r_pz positive")
    return arr


def obstacle_list(value: Any) -> list[Cylinder | Box]:
    items = [] if value is None else list(value)
    for i, item in enumerate(items):
        if not isinstance(item, (Cylinder, Box)):
            raise ValueError(f"obstacles[{i}]: expected Cylinder or Box, got {type(item).__name__}")
    return items


# ------------------------------------------------------------------------------ who senses whom


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


@dataclass
class SwarmInputs:
    """One ``select_many`` call's arguments, checked (``SwarmInputs.checked``): P, V, W (N, 3),
    R (N,), the obstacles, ``bounds`` (N, 6) (``bounds_array`` per vehicle), the deciding
    vehicles (``deciding`` (N,) bool, ``who`` their indices), the sensing parameters and the
    static spheres (S, 5)."""

    P: np.ndarray
    V: np.ndarray
    W: np.ndarray
    R: np.ndarray
    obstacles: list[Cylinder | Box]
    limits: Limits
    dt: float
    bounds: np.ndarray
    deciding: np.ndarray
    sensing_range: float
    max_neighbors: int | None
    obstacle_range: float | None
    spheres: np.ndarray

    @property
    def who(self) -> np.ndarray:
        return np.flatnonzero(self.deciding).astype(np.int64)

    @classmethod
    def checked(
        cls,
        positions: Any,
        velocities: Any,
        preferred_velocities: Any,
        r_pz: Any,
        obstacles: Any,
        limits: Any,
        dt: Any,
        sensing_range: Any,
        max_neighbors: Any,
        decide: Any,
        *,
        obstacle_range: Any = None,
        spheres: Any = None,
        max_speed: Any = None,
    ) -> SwarmInputs:
        """The arguments of ``select_many``, checked: ``ValueError`` naming a bad one."""
        P = points(positions, "positions")
        n = P.shape[0]
        limits = Limits() if limits is None else limits
        if not isinstance(limits, Limits):
            raise ValueError(f"limits: expected Limits, got {type(limits).__name__}")
        dt = positive_seconds(dt, "dt")
        return cls(
            P=P,
            V=points(velocities, "velocities", n),
            W=points(preferred_velocities, "preferred_velocities", n),
            R=radii(r_pz, "r_pz", n),
            obstacles=obstacle_list(obstacles),
            limits=limits,
            dt=float(dt),
            bounds=vehicle_limits(limits, float(dt), n, max_speed),
            deciding=mask(decide, "decide", n),
            sensing_range=distance(sensing_range, "sensing_range", allow_inf=True),
            max_neighbors=count(max_neighbors, "max_neighbors"),
            obstacle_range=None
            if obstacle_range is None
            else distance(obstacle_range, "obstacle_range", allow_inf=True),
            spheres=sphere_rows(spheres),
        )

    def links(self, threads: int = 1) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """(span, idx) of the deciding vehicles' neighbours, spheres and obstacles (``threads``:
        see ``vehicle_links``)."""
        who = self.who
        Pd = np.ascontiguousarray(self.P[who])
        return (
            vehicle_links(self.P, who, self.sensing_range, self.max_neighbors, threads),
            sphere_links(Pd, self.spheres, self.obstacle_range),
            obstacle_links(Pd, self.obstacles, self.obstacle_range),
        )

    def arrays(self, threads: int = 1) -> Swarm:
        """The ``Swarm`` arrays of the compiled call (``threads``: see ``vehicle_links``)."""
        agents = np.empty((self.P.shape[0], AGENT_COLUMNS))
        agents[:, 0:3], agents[:, 3:6], agents[:, 6:9] = self.P, self.V, self.W
        agents[:, 9], agents[:, 10] = self.R, self.deciding
        (nb_span, nb_idx), (sp_span, sp_idx), (ob_span, ob_idx) = self.links(threads)
        return Swarm(
            agents,
            self.bounds,
            self.who,
            nb_span,
            nb_idx,
            np.ascontiguousarray(self.spheres[:, [0, 1, 2, 4]]),
            sp_span,
            sp_idx,
            prism_rows(self.obstacles),
            ob_span,
            ob_idx,
        )

    def vehicle_limits(self, i: int) -> Limits:
        """Vehicle i's ``Limits`` (its own v_max under ``max_speed``)."""
        if self.bounds[i, 1] == self.limits.v_max:
            return self.limits
        return self.limits.model_copy(
            update={"speed": (self.limits.v_min, float(self.bounds[i, 1]))}
        )


# ------------------------------------------------------------------------------ threads

_pool_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None


def _workers(n: int) -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None or _pool._max_workers < n:  # noqa: SLF001 - grow to the threads asked for
            _pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="vo3d-swarm")
        return _pool


def cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def thread_count(threads: Any) -> int:
    """``threads`` checked (an integer in [1, ``cores()``]); None: every core."""
    limit = cores()
    if threads is None:
        return limit
    if (
        not isinstance(threads, numbers.Integral)
        or isinstance(threads, bool)
        or not 1 <= int(threads) <= limit
    ):
        raise ValueError(
            f"threads: must be an integer in [1, {limit}] (the cores this process may use), "
            f"got {threads!r}"
        )
    return int(threads)


__all__ = ["SwarmDecision", "SwarmInputs", "vehicle_links", "obstacle_links", "sphere_links"]
