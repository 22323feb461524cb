"""One compiled decision call for the deciding vehicles of several independent swarms.

``select_many`` decides for one swarm per call, and for a swarm of two vehicles almost all of
its time is the call itself (checking its arguments, a k-d tree, the answer's arrays), not the
decisions. :class:`BatchSelect` decides for the vehicles of many swarms that fly side by side
(``vo3d_opt.sim.lockstep``: one sweep encounter each) in one pass: it builds the compiled
kernel's arrays for all of them at once, each vehicle seeing only the vehicles, obstacles and
spheres of its own swarm, exactly as that swarm's own ``select_many`` would list them, and
runs the selector's compiled kernel over them, one range per set of planning options. Every
vehicle's velocity and status are bit for bit those of its swarm's ``select_many``
(tests/test_lockstep.py holds it to that).

It drives the kernel through the arrays ``select_many`` builds
(``formulations.swarm.Swarm``) and its range entry (``formulations.swarm.decide_range``).

:class:`SensedBatch` does the same for runs whose vehicles sense each other late or noisily
(``PerAgentSelect`` with a sensor): each vehicle's neighbours are the rows its own sensor
reports (``sim.sensed_batch``), decided in one compiled call for every run of the batch.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vo3d_opt.formulations.common import Config, Options
from vo3d_opt.formulations.swarm import (
    AGENT_COLUMNS,
    MANY_OUT_SIZE,
    Swarm,
    decide_range,
    neighbor_lists,
)
from vo3d_opt.geometry.pyramid import PRISM_WIDTH, prism_rows
from vo3d_opt.sim.deciders import PerAgentSelect, SwarmSelect
from vo3d_opt.sim.scenario import Scenario
from vo3d_opt.sim.sensed_batch import Fleet, Observer, decide_sensed
from vo3d_opt.swarm.checks import vehicle_limits
from vo3d_opt.swarm.sensing import sphere_links
from vo3d_opt.types import Box


def decides_in_batches(step: Any) -> bool:
    """Whether ``step`` decides as :class:`BatchSelect` can: a ``SwarmSelect`` whose selector
    runs compiled, with every vehicle in range as a neighbour (no ``max_neighbors``)."""
    return isinstance(step, SwarmSelect) and step.compiled and step.max_neighbors is None


def decides_sensed_in_batches(step: Any) -> bool:
    """Whether ``step`` decides as :class:`SensedBatch` can: a ``PerAgentSelect`` with a sensor
    whose decisions run compiled, every vehicle in one call (``one_call``)."""
    return isinstance(step, PerAgentSelect) and step.one_call


@dataclass(frozen=True)
class Member:
    """One swarm of a batch: its scenario and decision step, vehicles ``lo <= i < hi`` of the
    batch's arrays."""

    sc: Scenario
    step: SwarmSelect
    lo: int
    hi: int


def _empty_links(rows: int) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((rows, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)


class BatchSelect:
    """The deciding vehicles of every member in one pass per step (the module docstring).
    Built once per batch: the vehicles' limits and planning options, the pairs of vehicles
    that may sense each other (those of one member), the members' obstacles and spheres."""

    def __init__(self, members: Sequence[Member], n: int) -> None:
        self.members = list(members)
        self.n = n
        self.r_pz = np.zeros(n)
        self.limits = np.zeros((n, 6))
        self.group = np.full(n, -1, dtype=np.int64)
        self.configs: list[Config] = []
        keys: dict[Options, int] = {}
        pairs_a, pairs_b, ranges = [], [], []
        prisms, spheres = [], []
        self.prism_base, self.sphere_base = [], []
        m_prisms = m_spheres = 0
        for mem in self.members:
            sc, step = mem.sc, mem.step
            sl = slice(mem.lo, mem.hi)
            dt, rng = float(sc.dt), float(sc.sensing.vehicle_range)
            self.r_pz[sl] = sc.r_pz
            self.limits[sl] = vehicle_limits(step.limits, dt, sc.n_agents, step.top_speeds)
            for i in range(mem.lo, mem.hi):
                options = self._options(step, float(self.limits[i, 1]), dt, rng)
                self.group[i] = keys.setdefault(options, len(keys))
                if self.group[i] == len(self.configs):
                    self.configs.append(options.config)
            a, b = np.triu_indices(sc.n_agents, 1)
            pairs_a.append(a + mem.lo)
            pairs_b.append(b + mem.lo)
            ranges.append(np.full(a.shape, rng))
            self.prism_base.append(m_prisms)
            self.sphere_base.append(m_spheres)
            rows = prism_rows(step.obstacles)
            prisms.append(rows)
            spheres.append(step.spheres[:, [0, 1, 2, 4]])
            m_prisms += rows.shape[0]
            m_spheres += step.spheres.shape[0]
        self.pair_a = np.concatenate(pairs_a).astype(np.int64)
        self.pair_b = np.concatenate(pairs_b).astype(np.int64)
        self.pair_range = np.concatenate(ranges)
        self.prisms = np.ascontiguousarray(np.concatenate(prisms).reshape(-1, PRISM_WIDTH))
        self.spheres = np.ascontiguousarray(np.concatenate(spheres).reshape(-1, 4))
        self.member_of = np.zeros(n, dtype=np.int64)
        for f, mem in enumerate(self.members):
            self.member_of[mem.lo : mem.hi] = f
        self.with_spheres = [f for f, mem in enumerate(self.members) if len(mem.step.spheres)]
        self.obstacles = _ObstaclePairs(self.members, self.prism_base)

    @staticmethod
    def _options(step: SwarmSelect, top: float, dt: float, rng: float) -> Options:
        """The planning options ``select_many`` gives a deciding vehicle with top speed
        ``top`` (its own under a buffer in steps, else the limits'); equal options compare
        equal."""
        sel = step.selector
        if not sel.config.per_decision:
            top = step.limits.v_max
        return sel.options_for(top, dt, rng, step.limits.acceleration)

    def retire(self, members: Sequence[int]) -> None:
        """Forget the vehicle pairs of these members (done flying): fewer distances a step."""
        gone = np.isin(self.member_of[self.pair_a], np.asarray(members, dtype=np.int64))
        self.pair_a, self.pair_b = self.pair_a[~gone], self.pair_b[~gone]
        self.pair_range = self.pair_range[~gone]

    def decide(
        self, P: np.ndarray, V: np.ndarray, W: np.ndarray, deciding: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Commands (N, 3) (the current velocity of a vehicle that does not decide), kernel
        status codes (N,) (-1 where none) and the seconds the call took."""
        t0 = time.perf_counter()
        u, codes = V.copy(), np.full(self.n, -1, dtype=np.int64)
        who = np.flatnonzero(deciding)
        if not who.size:
            return u, codes, time.perf_counter() - t0
        who = who[np.argsort(self.group[who], kind="stable")].astype(np.int64)
        D = who.shape[0]
        place = np.full(self.n, -1, dtype=np.int64)
        place[who] = np.arange(D)
        # numpy's distance, as select_many's neighbour lists take it, pair by pair
        dist = np.linalg.norm(P[self.pair_a] - P[self.pair_b], axis=-1)
        near = dist <= self.pair_range
        nb_span = np.empty((D, 2), dtype=np.int64)
        nb_idx = neighbor_lists(
            self.pair_a[near], self.pair_b[near], dist[near], np.inf, place, -1, nb_span
        )
        (sp_span, sp_idx), (ob_span, ob_idx) = self._item_links(P, who)
        agents = np.empty((self.n, AGENT_COLUMNS))
        agents[:, 0:3], agents[:, 3:6], agents[:, 6:9] = P, V, W
        agents[:, 9], agents[:, 10] = self.r_pz, deciding
        sw = Swarm(
            agents,
            self.limits,
            who,
            nb_span,
            nb_idx,
            self.spheres,
            sp_span,
            sp_idx,
            self.prisms,
            ob_span,
            ob_idx,
        )
        out = np.empty((D, MANY_OUT_SIZE))
        groups = self.group[who]
        cuts = [0, *(np.flatnonzero(np.diff(groups)) + 1).tolist(), D]
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
            decide_range(sw, lo, hi, self.configs[groups[lo]], out)
        u[who] = out[:, :3]
        codes[who] = out[:, 3].astype(np.int64)
        return u, codes, time.perf_counter() - t0

    def _item_links(
        self, P: np.ndarray, who: np.ndarray
    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """(span, idx) of the spheres and of the obstacles each deciding vehicle takes into
        account: each member's own, within its obstacle range, as ``select_many`` lists them."""
        D = who.shape[0]
        spheres = _empty_links(D)
        if self.with_spheres:
            owner, parts = self.member_of[who], []
            for f in self.with_spheres:
                rows = np.flatnonzero(owner == f)
                if rows.size:
                    mem = self.members[f]
                    Pd = np.ascontiguousarray(P[who[rows]])
                    span, idx = sphere_links(Pd, mem.step.spheres, mem.sc.sensing.obstacle_range)
                    parts.append((rows, span, idx, self.sphere_base[f]))
            spheres = _merge(parts, D)
        return spheres, self.obstacles.links(P, who)


class _ObstaclePairs:
    """Every (vehicle, obstacle of its own member) pair of a batch, and which of them are
    within the member's obstacle range at a step: ``swarm.obstacle_links`` for all members at
    once. The surface distances are ``Cylinder.surface_distance`` and ``Box.surface_distance``,
    operation for operation, so each list holds exactly the obstacles ``select_many`` takes."""

    def __init__(self, members: Sequence[Member], prism_base: Sequence[int]) -> None:
        veh, obs, rng, shape = [], [], [], []
        for f, mem in enumerate(members):
            bodies = mem.step.obstacles
            if not bodies:
                continue
            limit = mem.sc.sensing.obstacle_range
            for m, body in enumerate(bodies):
                veh.append(np.arange(mem.lo, mem.hi))
                obs.append(np.full(mem.hi - mem.lo, prism_base[f] + m))
                rng.append(np.full(mem.hi - mem.lo, np.inf if limit is None else float(limit)))
                shape.append(np.tile(_shape_row(body), (mem.hi - mem.lo, 1)))
        self.count = len(veh)
        if not veh:
            return
        self.veh = np.concatenate(veh).astype(np.int64)
        self.obs = np.concatenate(obs).astype(np.int64)
        self.rng = np.concatenate(rng)
        self.shape = np.concatenate(shape)
        self.box = self.shape[:, 0] == 1.0

    def links(self, P: np.ndarray, who: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        D = who.shape[0]
        if not self.count:
            return _empty_links(D)
        place = np.full(P.shape[0], -1, dtype=np.int64)
        place[who] = np.arange(D)
        take = place[self.veh] >= 0
        rows, cols = place[self.veh[take]], self.obs[take]
        near = _surface_distance(P[self.veh[take]], self.shape[take], self.box[take])
        hit = near <= self.rng[take]
        rows, cols = rows[hit], cols[hit]
        order = np.lexsort((cols, rows))
        counts = np.bincount(rows, minlength=D)
        ends = np.cumsum(counts)
        span = np.stack([ends - counts, ends], axis=1).astype(np.int64)
        return span, np.ascontiguousarray(cols[order], dtype=np.int64)


def _shape_row(body: Any) -> np.ndarray:
    """kind (0 cylinder, 1 box), centre x, y, height, radius, half sides x, y, cos yaw, sin
    yaw: the numbers ``surface_distance`` computes with."""
    cx, cy = (float(c) for c in body.center)
    if isinstance(body, Box):
        hx, hy = (float(h) for h in body.size / 2.0)
        yaw = float(body.yaw)
        return np.array(
            [1.0, cx, cy, float(body.height), 0.0, hx, hy, math.cos(yaw), math.sin(yaw)]
        )
    return np.array([0.0, cx, cy, float(body.height), float(body.radius), 0.0, 0.0, 1.0, 0.0])


def _surface_distance(p: np.ndarray, shape: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Each point's distance to its own obstacle's surface: ``Cylinder.surface_distance`` where
    not ``box``, ``Box.surface_distance`` where ``box``, row by row."""
    out = np.empty(p.shape[0])
    vertical = np.maximum(p[:, 2] - shape[:, 3], 0.0) + np.maximum(-p[:, 2], 0.0)
    d = p[:, :2] - shape[:, 1:3]
    cyl = ~box
    if cyl.any():
        radial = np.maximum(np.linalg.norm(d[cyl], axis=-1) - shape[cyl, 4], 0.0)
        out[cyl] = np.hypot(radial, vertical[cyl])
    if box.any():
        db, c, s = d[box], shape[box, 7], shape[box, 8]
        local = np.stack([c * db[:, 0] + s * db[:, 1], -s * db[:, 0] + c * db[:, 1]], axis=-1)
        side = np.maximum(np.abs(local) - shape[box, 5:7], 0.0)
        out[box] = np.sqrt(np.sum(side**2, axis=-1) + vertical[box] ** 2)
    return out


def _merge(parts: list[Any], rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-member (rows, span, idx, base) lists as one (span (rows, 2), idx) over the batch."""
    span, chunks, m = np.zeros((rows, 2), dtype=np.int64), [], 0
    for at, sub_span, sub_idx, base in parts:
        span[at] = sub_span + m
        chunks.append(sub_idx + base)
        m += sub_idx.shape[0]
    idx = np.concatenate(chunks).astype(np.int64) if chunks else np.zeros(0, dtype=np.int64)
    return span, np.ascontiguousarray(idx)


@dataclass(frozen=True)
class SensedMember:
    """One run of a batch whose vehicles sense each other late or noisily: its scenario and
    decision step, vehicles ``lo <= i < hi`` of the batch's arrays."""

    sc: Scenario
    step: PerAgentSelect
    lo: int
    hi: int


class SensedBatch:
    """The deciding vehicles of several runs with noisy or late sensing in one compiled call
    per step: each run's step pushes its own sensor and lists what each of its vehicles
    senses (``PerAgentSelect.observers``, the rows ``PerAgentSelect`` decides from), offset
    into the batch's arrays; the kernel decides each vehicle from its own rows only, so every
    velocity and status is its run's own, bit for bit (tests/test_lockstep.py)."""

    def __init__(self, members: Sequence[SensedMember], n: int) -> None:
        self.members = list(members)
        self.n = n
        self.r_pz = np.zeros(n)
        # a vehicle of no member (a run in which nobody avoids) never decides: any row will do
        first = self.members[0].step
        self.bounds = np.tile(first.own_bounds[0], (n, 1))
        self.options: list[Options] = [first.own_options()[0]] * n
        self.sphere_base: list[int] = []
        self.prism_base: list[int] = []
        spheres: list[np.ndarray] = []
        prisms: list[np.ndarray] = []
        same: dict[Options, Options] = {}  # one object per set of options: one kernel call
        for mem in self.members:
            self.r_pz[mem.lo : mem.hi] = mem.sc.r_pz
            self.bounds[mem.lo : mem.hi] = mem.step.own_bounds
            self.options[mem.lo : mem.hi] = [same.setdefault(o, o) for o in mem.step.own_options()]
            self.sphere_base.append(sum(x.shape[0] for x in spheres))
            self.prism_base.append(sum(x.shape[0] for x in prisms))
            spheres.append(mem.step.sphere_rows)
            prisms.append(mem.step.prism_rows)
        self.spheres = np.ascontiguousarray(np.concatenate(spheres).reshape(-1, 4))
        self.prisms = np.ascontiguousarray(np.concatenate(prisms).reshape(-1, PRISM_WIDTH))
        self.retired: set[int] = set()

    def retire(self, members: Sequence[int]) -> None:
        """Stop sensing for these members (done flying)."""
        self.retired |= set(members)

    def decide(
        self, P: np.ndarray, V: np.ndarray, W: np.ndarray, deciding: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """As :meth:`BatchSelect.decide`; every member still flying senses this step's state
        (its sensor's clock is its steps), whether or not any of its vehicles decides."""
        t0 = time.perf_counter()
        u, codes = V.copy(), np.full(self.n, -1, dtype=np.int64)
        observers: list[Observer] = []
        for f, mem in enumerate(self.members):
            if f not in self.retired:
                observers += self._observers(f, mem, P, V, deciding)
        if observers:
            fleet = Fleet(P, V, W, self.r_pz, deciding, self.bounds, self.options)
            velocities, found = decide_sensed(fleet, observers, self.spheres, self.prisms)
            who = np.array([o.index for o in observers], dtype=np.int64)
            u[who], codes[who] = velocities, found
        return u, codes, time.perf_counter() - t0

    def _observers(
        self, f: int, mem: SensedMember, P: np.ndarray, V: np.ndarray, deciding: np.ndarray
    ) -> list[Observer]:
        """Member ``f``'s deciding vehicles' views, indices into the batch's arrays."""
        sl = slice(mem.lo, mem.hi)
        p = P[sl]
        obst, sph = mem.step.surfaces(p)
        assert mem.step.sensor is not None
        mem.step.sensor.push(p, V[sl])
        who = [i for i in mem.step.order if deciding[mem.lo + i]]
        at = (mem.lo, self.sphere_base[f], self.prism_base[f])
        return mem.step.observers(p, who, obst, sph, at=at)
