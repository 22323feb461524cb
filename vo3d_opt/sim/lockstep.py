"""Many independent runs flown side by side, one step of all of them at a time: a sweep's
encounters at the cost of far fewer Python calls.

A two-UAV encounter spends nearly all of its time in per-step overhead: a ``select_many`` call,
the preferred-velocity rule, the dynamics and the record, each on arrays of two rows.
:func:`fly_together` takes the runs a batch at a time and does each of those once per step for
every vehicle of the batch: the preferred velocities by one ``GoalWithDetours`` over all the
vehicles (its rule is per vehicle, and the runs share the clock), the decisions by one
:class:`~vo3d_opt.sim.batch_select.BatchSelect` pass (or, for runs with noisy or late sensing,
one :class:`~vo3d_opt.sim.batch_select.SensedBatch` pass), the dynamics and the arrivals as array
operations. Each run is :func:`~vo3d_opt.sim.simulator.fly`'s run of its scenario bit for bit
(the same positions, velocities, commands, statuses and arrivals; only the decision times
differ), which tests/test_lockstep.py checks: no vehicle sees another run's, and every
operation is the same arithmetic on each vehicle's numbers.

What it flies (:func:`fits`): kinematic or first-order dynamics, and either noiseless immediate
sensing with a step that is a compiled ``SwarmSelect`` (``decides_in_batches``), any sensing
with a compiled ``PerAgentSelect`` that decides every vehicle in one call
(``decides_sensed_in_batches``), or a step that nobody calls (every agent ``avoids: false``: a
run without avoidance). Anything else goes through ``fly``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vo3d_opt.sim.batch_select import (
    BatchSelect,
    Member,
    SensedBatch,
    SensedMember,
    decides_in_batches,
    decides_sensed_in_batches,
)
from vo3d_opt.sim.record import DecisionStep, RunRecord, Snapshot, StepDecision, check_allotment
from vo3d_opt.sim.safety import derive_margins
from vo3d_opt.sim.scenario import Scenario
from vo3d_opt.sim.sensed_batch import STATUS_NAMES
from vo3d_opt.sim.simulator import INVALID
from vo3d_opt.sim.traffic import GoalWithDetours, keep_watch


def fits_scenario(sc: Scenario, deciding: bool = True) -> bool:
    """Whether :func:`fly_together` can fly ``sc``: kinematic or first-order vehicles whose
    commands are never rate-limited and, when some of them decide (``deciding``), that sense
    the same true snapshot."""
    if sc.vehicle_dynamics.model not in ("kinematic", "first_order"):
        return False
    if deciding and not sc.sensing.perfect:
        return False
    return derive_margins(sc).command_rate is None


def fits(sc: Scenario, step: DecisionStep) -> bool:
    """Whether :func:`fly_together` flies ``sc`` with ``step`` as ``fly`` would (with nobody
    avoiding, nobody senses: the sensing does not matter; a step that senses for itself,
    ``decides_sensed_in_batches``, takes any sensing)."""
    if not sc.avoids.any() or decides_sensed_in_batches(step):
        return fits_scenario(sc, deciding=False)
    return fits_scenario(sc) and decides_in_batches(step)


@dataclass
class _Run:
    """One run of the batch: vehicles ``lo <= i < hi``, at most ``total`` steps."""

    sc: Scenario
    step: DecisionStep
    lo: int
    hi: int
    total: int
    steps: int = 0
    flying: bool = True


class _History:
    """Every step's arrays for every vehicle of the batch, [step, vehicle, ...]."""

    def __init__(self, steps: int, n: int) -> None:
        self.pos = np.empty((steps + 1, n, 3))
        self.vel = np.zeros((steps, n, 3))
        self.cmd = np.zeros((steps, n, 3))
        self.pref = np.zeros((steps, n, 3))
        self.decided = np.zeros((steps, n), dtype=bool)
        self.codes = np.zeros((steps, n), dtype=np.int64)  # into _Names (0: no decision)
        self.times = np.full((steps, n), np.nan)
        self.arrived = np.zeros((steps + 1, n), dtype=bool)


class _Names:
    """Status names by code: 0 is "" (no decision), 1.. the kernel's, then any other met."""

    def __init__(self) -> None:
        self.names = ["", *STATUS_NAMES]
        self.code = {name: c for c, name in enumerate(self.names)}

    def of(self, name: str) -> int:
        if name not in self.code:
            self.code[name] = len(self.names)
            self.names.append(name)
        return self.code[name]


def fly_together(runs: Sequence[tuple[Scenario, DecisionStep]]) -> list[RunRecord]:
    """The record of each (scenario, step) of ``runs``, as ``fly(sc, step)`` makes it (the
    module docstring); every scenario must :func:`fit <fits>` and all share one ``dt``."""
    if not runs:
        return []
    dts = {float(sc.dt) for sc, _ in runs}
    if len(dts) != 1:
        raise ValueError(f"dt: the runs flown together must share one, got {sorted(dts)}")
    batch, lo = [], 0
    for sc, step in runs:
        if not fits(sc, step):
            raise ValueError(f"{sc.name}: cannot be flown together with others (lockstep.fits)")
        check_allotment(sc.n_steps, sc.n_agents, sc.vehicle_dynamics.model == "kinematic")
        batch.append(_Run(sc, step, lo, lo + sc.n_agents, sc.n_steps))
        lo += sc.n_agents
    return _Batch(batch, dts.pop()).fly()


class _Batch:
    """The state of every vehicle of the runs (concatenated in run order) and their loop."""

    def __init__(self, runs: list[_Run], dt: float) -> None:
        self.runs, self.dt = runs, dt
        n = runs[-1].hi
        cat = np.concatenate
        self.goals = cat([r.sc.goals for r in runs])
        self.tol = cat([np.full(r.sc.n_agents, r.sc.goal_tolerance) for r in runs])
        self.straight = cat([~r.sc.avoids for r in runs])
        self.vrange = cat([np.full(r.sc.n_agents, r.sc.sensing.vehicle_range) for r in runs])
        self.run = cat([np.full(r.sc.n_agents, i) for i, r in enumerate(runs)])
        self.watching = np.zeros(n, dtype=bool)
        self.lagged = cat([np.full(r.sc.n_agents, _tau(r.sc) is not None) for r in runs])
        self.alpha = cat([np.full(r.sc.n_agents, _alpha(r.sc, dt)) for r in runs])
        speeds = cat([r.sc.cruise_speed for r in runs])  # fly's rule: scenario_goal_velocity
        self.prefer = GoalWithDetours(self.goals, speeds, dt, near=cat([r.sc.r_pz for r in runs]))
        self.deciders = [r for r in runs if r.sc.avoids.any()]
        self.select = _batch_select(self.deciders, n)
        self.retired: set[int] = set()
        self.hist = _History(max(r.total for r in runs), n)
        self.names = _Names()
        self.n = n

    def fly(self) -> list[RunRecord]:
        t_start = time.perf_counter()
        p = np.concatenate([r.sc.starts for r in self.runs]).astype(float)
        v = np.zeros_like(p)
        done = np.linalg.norm(p - self.goals, axis=1) <= self.tol
        held = done.copy()
        self.hist.pos[0], self.hist.arrived[0] = p, done
        for r in self.runs:
            r.flying = not done[r.lo : r.hi].all()
        for k in range(self.hist.vel.shape[0]):
            active = np.zeros(self.n, dtype=bool)
            self.watching = keep_watch(
                p,
                self.goals,
                done=done,
                straight=self.straight,
                watching=self.watching,
                tolerance=self.tol,
                vehicle_range=self.vrange,
                run=self.run,
                stuck=self.prefer.stuck,
            )
            for r in self.runs:  # a run ends when everyone is home and nobody keeps watch
                home = done[r.lo : r.hi].all() and not self.watching[r.lo : r.hi].any()
                r.flying = r.flying and k < r.total and not home
                active[r.lo : r.hi] = r.flying
            if not active.any():
                break
            p, v = self._step(k, p, v, done, held, active)
            for r in self.runs:
                if r.flying:
                    r.steps = k + 1
            self._retire()
        share = (time.perf_counter() - t_start) / len(self.runs)
        return [self._record(r, share) for r in self.runs]

    def _retire(self) -> None:
        """Let the decisions forget the runs that finished."""
        ended = {f for f, r in enumerate(self.deciders) if not r.flying} - self.retired
        if ended and self.select is not None:
            self.select.retire(sorted(ended))
            self.retired |= ended

    def _step(
        self,
        k: int,
        p: np.ndarray,
        v: np.ndarray,
        done: np.ndarray,
        held: np.ndarray,
        active: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Step k of every run still flying (``fly``'s loop body); updates ``done`` and
        ``held`` in place, returns the new positions and velocities."""
        h, dt = self.hist, self.dt
        watching = self.watching
        home = done & ~watching & ~held  # home again, nothing in range: it stops and hovers
        held &= ~watching  # back to deciding, from hover (v is 0 since it was held)
        held |= home
        v = np.where(home[:, None], 0.0, v)
        w = np.asarray(self.prefer(p), dtype=float)
        w[done & ~watching] = 0.0
        deciding = (~done | watching) & ~self.straight & active
        waiting = self.prefer.waiting & deciding & ~done
        if self.select is not None:
            u, codes, took = self.select.decide(p, v, w, deciding)
        else:
            u, codes, took = v.copy(), np.full(self.n, -1, dtype=np.int64), 0.0
        if waiting.any():
            self._land(k, p, v, w, deciding, waiting, u, codes)
        codes = codes + 1  # kernel code c is name c + 1 here
        bad = deciding & ~np.all(np.isfinite(u), axis=1)
        for i in np.flatnonzero(bad):
            codes[i] = self.names.of(f"{INVALID} ({self.names.names[codes[i]]})")
        u[bad | ~deciding] = 0.0
        u[self.straight] = w[self.straight]
        h.pref[k], h.cmd[k], h.decided[k] = w, u, deciding
        h.codes[k] = np.where(deciding, codes, 0)
        h.times[k] = np.where(deciding, took / max(1, int(deciding.sum())), np.nan)
        # the dynamics: kinematic flies the command, first-order closes on it (dynamics.py)
        flown = np.where(self.lagged[:, None], v + (u - v) * self.alpha[:, None], u)
        flown[held] = 0.0
        p = p + flown * dt
        h.vel[k] = flown
        at_goal = np.linalg.norm(p - self.goals, axis=1) <= self.tol
        arrived = ~done & at_goal
        done |= arrived
        held |= arrived
        v = flown.copy()
        v[arrived] = 0.0
        h.pos[k + 1], h.arrived[k + 1] = p, done & (at_goal | ~watching)
        return p, v

    def _land(
        self,
        k: int,
        p: np.ndarray,
        v: np.ndarray,
        w: np.ndarray,
        deciding: np.ndarray,
        waiting: np.ndarray,
        u: np.ndarray,
        codes: np.ndarray,
    ) -> None:
        """The landing steps of the runs with agents waiting at their goal's door, each by its
        own decision step (``SwarmSelect._land``), into ``u``."""
        for r in self.runs:
            s = slice(r.lo, r.hi)
            if not (r.flying and waiting[s].any()):
                continue
            snap = Snapshot(
                k=k,
                t=k * self.dt,
                positions=p[s].copy(),
                velocities=v[s].copy(),
                preferred=w[s].copy(),
                deciding=deciding[s].copy(),
                waiting=waiting[s].copy(),
            )
            names = np.array([self.names.names[c + 1] for c in codes[s]])
            out = StepDecision(u[s].copy(), names, np.full(r.hi - r.lo, np.nan), np.zeros(0))
            u[s] = r.step._land(snap, out).commands  # type: ignore[attr-defined]

    def _record(self, r: _Run, wall: float) -> RunRecord:
        """Run ``r``'s record, as ``fly``'s buffers leave it."""
        h, s, sl = self.hist, r.steps, slice(r.lo, r.hi)
        decided = h.decided[:s, sl].copy()
        names, codes = _local_codes(h.codes[:s, sl], decided, self.names.names)
        velocities = h.vel[:s, sl].copy()
        kinematic = r.sc.vehicle_dynamics.model == "kinematic"
        times = h.times[:s, sl].copy()
        return RunRecord(
            scenario=r.sc,
            formulation=r.step.formulation,
            solver=r.step.solver,
            times=np.arange(s + 1) * r.sc.dt,
            positions=h.pos[: s + 1, sl].copy(),
            velocities=velocities,
            commands=velocities if kinematic else h.cmd[:s, sl].copy(),
            preferred=h.pref[:s, sl].copy(),
            decided=decided,
            status_codes=codes,
            status_names=names,
            decision_times=times,
            solve_times=times,
            arrived=h.arrived[: s + 1, sl].copy(),
            wall_time=wall,
            extra=r.step.extra(),
        )


def _batch_select(deciders: list[_Run], n: int) -> BatchSelect | SensedBatch | None:
    """One decision pass for the deciding runs: from the true snapshot, or each run from its
    own sensor (a batch holds one kind)."""
    if not deciders:
        return None
    sensed = [decides_sensed_in_batches(r.step) for r in deciders]
    if all(sensed):
        return SensedBatch([SensedMember(r.sc, r.step, r.lo, r.hi) for r in deciders], n)  # type: ignore[arg-type]
    if any(sensed):
        raise ValueError("runs that sense for themselves fly in batches of their own")
    return BatchSelect([Member(r.sc, r.step, r.lo, r.hi) for r in deciders], n)  # type: ignore[arg-type]


def _tau(sc: Scenario) -> float | None:
    dyn = sc.vehicle_dynamics
    return float(dyn.tau) if dyn.model == "first_order" and dyn.tau is not None else None


def _alpha(sc: Scenario, dt: float) -> float:
    """The first-order model's share of the gap closed per step, ``min(1, dt / tau)``."""
    tau = _tau(sc)
    return 1.0 if tau is None else min(1.0, dt / tau)


def _local_codes(
    codes: np.ndarray, decided: np.ndarray, names: list[str]
) -> tuple[tuple[str, ...], np.ndarray]:
    """A run's status names and codes as ``RunBuffers.put_statuses`` numbers them: "" first,
    then each name at the step it first appears, those new at one step in name order."""
    present = np.unique(codes[decided])
    first = []
    for c in present:
        hit = decided & (codes == c)
        first.append((int(np.argmax(hit.any(axis=1))), names[c], int(c)))
    order = sorted(first)
    local = np.zeros(len(names), dtype=np.uint16)
    for m, (_, _, c) in enumerate(order, start=1):
        local[c] = m
    out = np.where(decided, local[codes], 0).astype(np.uint16)
    return ("", *(name for _, name, _ in order)), out
