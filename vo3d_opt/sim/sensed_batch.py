"""Every deciding vehicle of a run with noisy or late sensing in one compiled call.

With sensing noise or latency each vehicle sees the others differently (``sim.sensing``), which
one ``select_many`` call, whose vehicles all see one snapshot, cannot express; so
``PerAgentSelect`` calls ``select`` once per vehicle, with a ``Neighbor`` per vehicle sensed.
When the selector's decision is compiled, :func:`decide_sensed` builds the compiled kernel's
arrays instead (``formulations.swarm.Swarm``): the vehicles' own rows first, then one row per
(observer, vehicle it senses) holding what that observer senses of it, and each observer's
neighbours are its own rows. The kernel builds a neighbour's row from those columns exactly as
``select`` builds it from the ``Neighbor`` (position, velocity, the pair's larger r_pz,
cooperative), in the same order, then the spheres and the obstacles as ``select`` is given
them, with the same planning options: every velocity and status is ``select``'s, bit for bit
(tests/test_sensed_batch.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vo3d_opt.formulations.common import Options
from vo3d_opt.formulations.inputs import bounds_row
from vo3d_opt.formulations.swarm import AGENT_COLUMNS, MANY_OUT_SIZE, Swarm, decide_many
from vo3d_opt.status import DECISION_STATUSES
from vo3d_opt.types import Limits

#: The kernel's status codes as names: code c is ``STATUS_NAMES[c]``.
STATUS_NAMES = np.array([str(s) for s in DECISION_STATUSES], dtype=object)


@dataclass(frozen=True)
class Observer:
    """One deciding vehicle's view: the vehicles it senses (indices, index order) with the
    positions and velocities it senses them at, and the spheres and obstacles in its range
    (indices into the step's sphere and prism tables)."""

    index: int
    sensed: np.ndarray  # (k,) int: vehicle indices
    positions: np.ndarray  # (k, 3)
    velocities: np.ndarray  # (k, 3)
    spheres: np.ndarray  # (s,) int
    obstacles: np.ndarray  # (o,) int


@dataclass(frozen=True)
class Fleet:
    """The vehicles' own state this step: true positions and velocities, preferred velocities,
    r_pz, who decides (a vehicle that does not is sensed as not avoiding), and each one's
    limits as the kernel's bounds rows (N, 6) (:func:`bounds_rows`) and planning options
    (``VelocitySelector.options_for``)."""

    positions: np.ndarray
    velocities: np.ndarray
    preferred: np.ndarray
    r_pz: np.ndarray
    deciding: np.ndarray
    bounds: np.ndarray
    options: Sequence[Options]


def bounds_rows(limits: Sequence[Limits], dt: float) -> np.ndarray:
    """Each vehicle's limits as the kernel's bounds row (``inputs.bounds_row``): (N, 6)."""
    return np.array([bounds_row(lim, dt) for lim in limits], dtype=float).reshape(-1, 6)


def _spans(lists: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(span, idx) of index lists, one per deciding vehicle."""
    sizes = np.array([len(x) for x in lists], dtype=np.int64)
    ends = np.cumsum(sizes)
    span = np.ascontiguousarray(np.stack([ends - sizes, ends], axis=1).reshape(-1, 2))
    idx = np.concatenate([*(np.asarray(x, dtype=np.int64) for x in lists), np.zeros(0, np.int64)])
    return span, idx


def sensed_swarm(
    fleet: Fleet, observers: Sequence[Observer], spheres: np.ndarray, prisms: np.ndarray
) -> Swarm:
    """The kernel's arrays: the vehicles' rows, then each observer's sensed rows (its
    neighbours); ``spheres`` (S, 4) x, y, z, r_pz; ``prisms`` (M, 6)."""
    n = fleet.positions.shape[0]
    counts = [len(o.sensed) for o in observers]
    rows = n + sum(counts)
    agents = np.zeros((rows, AGENT_COLUMNS))
    agents[:n, 0:3], agents[:n, 3:6] = fleet.positions, fleet.velocities
    agents[:n, 6:9], agents[:n, 9], agents[:n, 10] = fleet.preferred, fleet.r_pz, fleet.deciding
    nb_lists, start = [], n
    for o, count in zip(observers, counts, strict=True):
        block = agents[start : start + count]
        block[:, 0:3], block[:, 3:6] = o.positions, o.velocities
        block[:, 9], block[:, 10] = fleet.r_pz[o.sensed], fleet.deciding[o.sensed]
        nb_lists.append(np.arange(start, start + count))
        start += count
    limits = np.zeros((rows, 6))
    limits[:n] = fleet.bounds
    nb_span, nb_idx = _spans(nb_lists)
    sp_span, sp_idx = _spans([o.spheres for o in observers])
    ob_span, ob_idx = _spans([o.obstacles for o in observers])
    who = np.array([o.index for o in observers], dtype=np.int64)
    return Swarm(
        agents,
        limits,
        who,
        nb_span,
        nb_idx,
        np.ascontiguousarray(spheres, dtype=float),
        sp_span,
        sp_idx,
        np.ascontiguousarray(prisms, dtype=float),
        ob_span,
        ob_idx,
    )


def decide_sensed(
    fleet: Fleet, observers: Sequence[Observer], spheres: np.ndarray, prisms: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each observer's velocity (D, 3) and kernel status code (D,) (``STATUS_NAMES[c]``), in
    ``observers``' order: one compiled call per options object of ``fleet.options``, on the
    calling thread (a run's vehicles are few; a sweep runs its encounters in parallel)."""
    sw = sensed_swarm(fleet, observers, spheres, prisms)
    out = np.empty((len(observers), MANY_OUT_SIZE))
    # options_for hands out one object per set of options: grouping by the object is cheap,
    # and two equal objects would only cost two calls with the same answers
    by_options: dict[int, list[int]] = {}
    for d, o in enumerate(observers):
        by_options.setdefault(id(fleet.options[o.index]), []).append(d)
    for ds in by_options.values():
        rows = np.array(ds, dtype=np.int64)
        part = sw._replace(
            who=sw.who[rows],
            nb_span=sw.nb_span[rows],
            sp_span=sw.sp_span[rows],
            ob_span=sw.ob_span[rows],
        )
        out[rows] = decide_many(part, fleet.options[observers[ds[0]].index].config, 1)
    return out[:, :3], out[:, 3].astype(np.int64)
