"""``select_many``'s compiled side: every deciding vehicle of a swarm in one call.

The Python side (``vo3d_opt.swarm``) finds who senses whom with a k-d tree and hands the answer
over as index lists (a vehicle's neighbours are ``nb_idx[nb_span[d, 0]:nb_span[d, 1]]``, the
same for the static spheres and the obstacles). The compiled core
(``vo3d_opt/algorithm/swarm.hpp``) builds each deciding vehicle's ``nbrs`` and ``prisms`` rows
from those lists and decides for it exactly what ``select`` computes for that vehicle, with no
Python object per vehicle or neighbour, on several threads (the GIL released; the vehicles are
independent, so the answers do not depend on the number of threads).

``neighbor_lists`` turns the k-d tree's pairs into those lists (a counting sort by vehicle),
``nearest_lists`` ranks the tree's k-nearest proposals in a crowd; both compiled too.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import vo3d_opt._core as _core

from .common import Config

#: Columns of ``Swarm.agents``: position (3), velocity (3), preferred velocity (3), r_pz,
#: cooperative (1: it decides, 0: it keeps its velocity whatever the others do).
AGENT_COLUMNS: int = _core.AGENT_COLUMNS
#: ``decide_range``'s output row: ``kernel.decide``'s (velocity, status, phi, round, solved),
#: then the vehicles and the static zones (spheres and obstacles) the vehicle took into account.
MANY_OUT_SIZE: int = _core.MANY_OUT_SIZE


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
    prisms: np.ndarray  # (M, 6): ``prism_rows`` of the obstacles
    ob_span: np.ndarray  # (D, 2) int64 into ob_idx
    ob_idx: np.ndarray  # (G,) int64


#: (dtype, dimensions) of each field of ``Swarm``, all C-contiguous (``SwarmInputs.arrays``
#: builds them so; the core checks them).
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


def decide_many(sw: Swarm, cfg: Config, threads: int) -> np.ndarray:
    """Every deciding vehicle of ``sw``: row d of the result (D, MANY_OUT_SIZE) for vehicle
    who[d], on ``threads`` threads (the calling one among them)."""
    out = np.empty((sw.who.shape[0], MANY_OUT_SIZE))
    _core.decide_many(sw, cfg, int(threads), out)
    return out


def decide_range(sw: Swarm, lo: int, hi: int, cfg: Config, out: np.ndarray) -> None:
    """Deciding vehicles lo <= d < hi of ``sw`` only, into rows lo..hi-1 of ``out`` (D,
    MANY_OUT_SIZE), on the calling thread."""
    _core.decide_many(sw, cfg, 1, out, int(lo), int(hi))


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
    return _core.neighbor_lists(a, b, dist, float(sensing_range), place, int(k), span)


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
    the tree's distances), ranked by numpy's distance (its squares summed left to right), into
    ``chosen`` (D, k) in increasing index order (n for none). Returns whether each list is
    settled: whether every vehicle the tree did not propose lies clearly beyond the k-th
    nearest (or the range), so that no tie hides beyond the proposals
    (``vo3d_opt.swarm._nearest_links`` ranks the others anew). Releases the GIL."""
    return _core.nearest_lists(P, who, near, far, float(sensing_range), chosen)
