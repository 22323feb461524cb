"""``select_many`` itself: every deciding vehicle in one compiled call (plane_qp on exact2d,
parallel over vehicles), or ``select`` for each in turn (any other formulation or backend),
with the same neighbours and the same answers."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from ..formulations import kernel
from ..formulations.common import Options
from ..formulations.swarm import MANY_OUT_SIZE, decide_many
from ..status import DECISION_STATUSES
from ..types import AgentState, Neighbor
from .inputs import SwarmDecision, SwarmInputs

#: The options a decision with top speed v_max and period dt plans with, given the sensing
#: range and the acceleration limit (None: none): ``VelocitySelector.options_for``.
OptionsFor = Callable[[float, float, float | None, float | None], Options]


class Answer(Protocol):
    """What ``select_many_loop`` reads of a ``select`` answer (``Decision``)."""

    velocity: np.ndarray
    status: Any
    solve_time: float
    plane: float | None
    info: dict


def options_by_vehicle(
    inputs: SwarmInputs, options_for: OptionsFor, per_decision: bool
) -> list[tuple[Options, np.ndarray]]:
    """The deciding vehicles grouped by the options they plan with (their own top speed may
    set the buffer and the horizon when ``per_decision``; the acceleration limit is the
    swarm's): (options, the rows of ``who`` that use them)."""
    v_max = inputs.bounds[inputs.who, 1]
    groups = np.unique(v_max) if per_decision else v_max[:0]
    dt, rng, acc = inputs.dt, inputs.sensing_range, inputs.limits.acceleration
    if groups.size <= 1:
        top = float(groups[0]) if groups.size else inputs.limits.v_max
        return [(options_for(top, dt, rng, acc), np.arange(inputs.who.shape[0]))]
    return [(options_for(float(v), dt, rng, acc), np.flatnonzero(v_max == v)) for v in groups]


def select_many_compiled(
    groups: list[tuple[Options, np.ndarray]], inputs: SwarmInputs, threads: int, t0: float
) -> SwarmDecision:
    """Every deciding vehicle compiled, on ``threads`` threads; ``groups``: the options and
    the deciding vehicles (rows of ``who``) that plan with them (``options_by_vehicle``)."""
    sw = inputs.arrays(threads)
    if len(groups) == 1:
        out = decide_many(sw, groups[0][0].config, threads)
    else:
        out = np.empty((sw.who.shape[0], MANY_OUT_SIZE))
        for options, rows in groups:
            part = sw._replace(
                who=sw.who[rows],
                nb_span=sw.nb_span[rows],
                sp_span=sw.sp_span[rows],
                ob_span=sw.ob_span[rows],
            )
            out[rows] = decide_many(part, options.config, threads)
    result = swarm_decision(
        inputs.V,
        sw.who,
        out[:, :3],
        _STATUS_NAMES[out[:, 3].astype(np.int64)],
        _ROUND_NAMES[out[:, 5].astype(np.int64)],
        out[:, 4],
        out[:, 7:9].astype(np.int64),
        out[:, 6].astype(np.int64),
    )
    result.compiled, result.threads = True, threads
    result.solve_time = time.perf_counter() - t0
    result.times[sw.who] = result.solve_time / max(1, sw.who.shape[0])
    return result


_STATUS_NAMES = np.array([str(s) for s in DECISION_STATUSES])
_ROUND_NAMES = np.array(kernel.ROUND_NAMES)


def select_many_loop(
    select: Callable[..., Answer], inputs: SwarmInputs, t0: float
) -> SwarmDecision:
    """``select`` for each deciding vehicle with the same neighbours (formulations and
    backends that cannot run compiled)."""
    P, V, W, R = inputs.P, inputs.V, inputs.W, inputs.R
    who = inputs.who
    (nb_span, nb_idx), (sp_span, sp_idx), (ob_span, ob_idx) = inputs.links()
    spheres = [
        Neighbor(position=s[:3], velocity=(0.0, 0.0, 0.0), r_pz=float(s[4]), cooperative=False)
        for s in inputs.spheres
    ]
    D = who.shape[0]
    vel, statuses, rounds = (
        np.empty((D, 3)),
        np.empty(D, dtype=object),
        np.empty(D, dtype=object),
    )
    planes, counts = np.full(D, np.nan), np.zeros((D, 2), dtype=np.int64)
    solved, times = np.zeros(D, dtype=np.int64), np.empty(D)
    for d, i in enumerate(who):
        nbrs = [
            Neighbor(
                position=P[j],
                velocity=V[j],
                r_pz=float(max(R[i], R[j])),
                cooperative=bool(inputs.deciding[j]),
            )
            for j in nb_idx[nb_span[d, 0] : nb_span[d, 1]]
        ]
        nbrs += [spheres[k] for k in sp_idx[sp_span[d, 0] : sp_span[d, 1]]]
        obs = [inputs.obstacles[m] for m in ob_idx[ob_span[d, 0] : ob_span[d, 1]]]
        dec = select(
            AgentState(position=P[i], velocity=V[i]),
            W[i],
            nbrs,
            obs,
            inputs.vehicle_limits(i),
            inputs.dt,
            sensing_range=inputs.sensing_range,
        )
        vel[d], statuses[d], rounds[d] = (
            dec.velocity,
            str(dec.status),
            str(dec.info.get("round", "")),
        )
        planes[d] = np.nan if dec.plane is None else dec.plane
        counts[d] = (nb_span[d, 1] - nb_span[d, 0], len(obs) + sp_span[d, 1] - sp_span[d, 0])
        solved[d], times[d] = int(dec.info.get("solved", 0)), dec.solve_time
    result = swarm_decision(
        V, who, vel, statuses.astype(str), rounds.astype(str), planes, counts, solved
    )
    result.times[who] = times
    result.solve_time = time.perf_counter() - t0
    return result


def _names(n: int, who: np.ndarray, names: np.ndarray) -> np.ndarray:
    """(n,) str: ``names`` (D,) at ``who``, "" elsewhere."""
    names = np.asarray(names, dtype=str)
    out = np.full(n, "", dtype=names.dtype if names.size else "<U1")
    out[who] = names
    return out


def swarm_decision(
    V: np.ndarray,
    who: np.ndarray,
    vel: np.ndarray,
    statuses: np.ndarray,
    rounds: np.ndarray,
    planes: np.ndarray,
    counts: np.ndarray,
    solved: np.ndarray,
) -> SwarmDecision:
    """A ``SwarmDecision`` of N vehicles from the deciding vehicles' (D,) answers; the others
    keep their velocity ``V``."""
    n = V.shape[0]
    out = SwarmDecision(
        velocities=V.copy(),
        statuses=_names(n, who, statuses),
        solve_time=0.0,
        decided=np.zeros(n, dtype=bool),
        rounds=_names(n, who, rounds),
        planes=np.full(n, np.nan),
        neighbors=np.zeros(n, dtype=np.int64),
        obstacles=np.zeros(n, dtype=np.int64),
        solved=np.zeros(n, dtype=np.int64),
        times=np.full(n, np.nan),
    )
    out.velocities[who], out.planes[who] = vel, planes
    out.neighbors[who], out.obstacles[who], out.solved[who] = counts[:, 0], counts[:, 1], solved
    out.decided[who] = True
    return out
