"""Decentralised multi-UAV simulation (paper section 5): one loop, sense → decide → integrate.

"Each UAV independently produces avoiding velocity control based on its own detection of
obstacles ... moves at a constant time step ... the avoiding velocity control is updated at each
time step." Here, every ``dt`` (:func:`fly`):

1. **sense**: the snapshot of the previous step (positions, velocities), the same for everyone,
   so the order of the decisions does not matter; each agent's preferred velocity comes from a
   function of the positions (default :class:`vo3d_opt.sim.traffic.GoalWithDetours`: towards
   the goal at ``min(v_max, distance / dt)``, turned right for a while after an agent has
   stalled for 4 s; 0 for arrived agents);
2. **decide**: a pluggable :class:`DecisionStep` turns the snapshot into one command per agent
   that has not arrived: our selector for the whole swarm in one ``select_many`` call
   (:class:`vo3d_opt.sim.deciders.SwarmSelect`, what ``run_scenario`` and ``vo3d run`` use),
   any ``SelectorLike`` called once per agent (:class:`~vo3d_opt.sim.deciders.PerAgentSelect`),
   or RVO2-3D (:class:`vo3d_opt.baselines.rvo2.RVO2Step`);
3. **integrate**: ``vo3d_opt.sim.dynamics``, the scenario's ``dynamics`` and ``wind``
   (``kinematic``: ``p += v_cmd dt``; ``first_order`` (or ``velocity_response_tau``):
   ``v += (v_cmd - v) min(1, dt / tau)``, ``p += v dt``; ``rotorpy``: RotorPy multirotors,
   whose sub-step samples are recorded in ``RunRecord.samples`` and judged by the metrics;
   their commands, whoever gave them, change at most ``safety.command_rate`` per period).

Agents with ``avoids: false`` never decide: they fly their preferred (straight-to-goal)
velocity and the others see them as non-cooperative, as arrived ones. With sensing noise or
latency each agent decides from its own view of the others (``deciders.decision_step``). The
selector plans with the margins ``vo3d_opt.sim.safety`` derives from the scenario (acceleration
bound, pz_buffer, altitude margin, obstacle prisms; ``formulations/real_world.md``).

What an agent senses (both selector steps apply the same rules; ``vo3d_opt.swarm`` documents
them): the other vehicles within ``sensing.vehicle_range`` (centre distance), as neighbours with
their current velocity and ``r_pz = max(own r_pz, their r_pz)`` (so each side keeps the larger
zone, which is what the metrics count); arrived ones as non-cooperative (they hover and no
longer avoid, so a ``reciprocal`` selector takes all of the avoidance, not half); the obstacles
within ``sensing.obstacle_range`` of their nearest point (those with ``sensed: false`` are never
seen), and the scenario's static spheres within that range as zero-velocity, non-cooperative
neighbours; its limits: speed ``(limits.speed[0], min(limits.speed[1], max_speed))`` and the
altitude range.

An agent within ``goal_tolerance`` of its goal has arrived: it stops (velocity 0 from that
sample on, which is what the others sense next), hovers there for the rest of the run, still
seen by the others, and no longer decides. The run stops when all agents have arrived or after
``max_time``. The loop never clips a decision: the metrics report any limit it breaks (a
non-finite command becomes 0 with the status ``invalid_velocity (...)``).
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from vo3d_opt.config import DEFAULT_PRESET
from vo3d_opt.sim.dynamics import Dynamics, make_dynamics
from vo3d_opt.sim.safety import derive_margins, within_reach
from vo3d_opt.sim.scenario import Scenario, load_scenario
from vo3d_opt.sim.spill import (
    SPILL_BYTES,
    Spill,
    array_bytes,
    in_memory_fs,
    spill_directory,
    spill_supported,
)
from vo3d_opt.sim.traffic import GoalWithDetours
from vo3d_opt.types import AgentState, Limits, Neighbor

#: Default formulation when neither the caller nor the scenario names one (contract §1).
DEFAULT_FORMULATION = "plane_qp"
#: The status of a command that was not a finite 3-vector (replaced by 0).
INVALID = "invalid_velocity"


class Decision(Protocol):
    velocity: Any
    status: str
    solve_time: float


class SelectorLike(Protocol):
    """Anything with ``VelocitySelector.select``'s signature (contract §1)."""

    def select(
        self,
        *,
        own: AgentState,
        preferred_velocity: Any,
        neighbors: list[Neighbor],
        obstacles: list[Any],
        limits: Limits,
        dt: float,
    ) -> Decision: ...


@dataclass(frozen=True)
class Snapshot:
    """What the agents sense at step ``k`` (time ``t``): everyone's ``positions`` and
    ``velocities`` (N, 3), their ``preferred`` velocities (N, 3; 0 for arrived agents) and which
    of them decide (``deciding`` (N,): those that have not arrived); ``waiting`` (N,) the
    deciding agents that stalled at their goal's door, when the preferred-velocity rule says
    (``GoalWithDetours.waiting``; None otherwise)."""

    k: int
    t: float
    positions: np.ndarray
    velocities: np.ndarray
    preferred: np.ndarray
    deciding: np.ndarray
    waiting: np.ndarray | None = None


@dataclass
class StepDecision:
    """A decision step's answer: ``commands`` (N, 3) m/s (rows of agents that do not decide are
    ignored), ``statuses`` (N,) str, ``decision_times`` and ``solve_times`` (N,) s (NaN where
    an agent did not decide)."""

    commands: np.ndarray
    statuses: np.ndarray
    decision_times: np.ndarray
    solve_times: np.ndarray


class DecisionStep(Protocol):
    """The pluggable decision of :func:`fly`. ``formulation`` and ``solver`` name it in the
    record; ``extra()`` adds to ``RunRecord.extra`` at the end of the run."""

    formulation: str
    solver: str

    def decide(self, snap: Snapshot) -> StepDecision: ...

    def extra(self) -> dict[str, Any]: ...


@dataclass
class RunRecord:
    """Everything a run produced; arrays indexed [step, agent, ...] in the scenario's agent order.

    ``positions[k]`` is the state at ``times[k]`` (k = 0..T); ``commands[k]`` the decision taken
    at ``times[k]`` and ``velocities[k]`` the velocity flown over [t_k, t_k+1] (under kinematic
    dynamics the command itself: then ``commands`` is the same array as ``velocities``; 0 for
    arrived agents). ``decided[k, i]`` says whether agent i decided at step k; ``statuses``,
    ``decision_times`` (wall time of its decision, s: the ``select()`` call, or its equal share
    of the step's ``select_many()`` or ``doStep()`` call) and ``solve_times`` (the decision's
    own ``solve_time``; the same array as ``decision_times`` when every step said the same)
    are "" / NaN where it did not. The statuses are kept as ``status_codes`` (T, N) into
    ``status_names`` (whose first is "", no decision); ``statuses`` spells them out (an object
    array, built at each call).

    A long run of a large swarm keeps its arrays in a temporary file (``spill``,
    :mod:`vo3d_opt.sim.spill`): they read as any array; :meth:`drop_resident` lets go of the
    pages read so far (the metrics and the writers call it as they go). The file is mapped
    shared: a process forked while the record lives (``multiprocessing``'s ``fork``) sees the
    same arrays, and what it writes into them the parent sees too; a pickled record (``spawn``,
    Dask) carries copies of their contents instead.
    """

    scenario: Scenario
    formulation: str
    solver: str
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    commands: np.ndarray
    preferred: np.ndarray
    decided: np.ndarray
    status_codes: np.ndarray
    status_names: tuple[str, ...]
    decision_times: np.ndarray
    solve_times: np.ndarray
    arrived: np.ndarray
    wall_time: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)
    #: The real trajectory between the control steps when the dynamics sample it more finely
    #: (rotorpy's sub-steps): positions and velocities (T S + 1, N, 3), row ``k S`` the state
    #: at ``times[k]``; None when the steps are the samples (kinematic, first_order).
    samples: np.ndarray | None = None
    sample_velocities: np.ndarray | None = None
    #: The temporary file holding the arrays, when the run spilled them (None: in memory).
    spill: Spill | None = field(default=None, repr=False, compare=False)
    #: What the metrics computed once for this record (``metrics.record_close_pairs``).
    cache: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.status_names or self.status_names[0] != "":
            raise ValueError('status_names: the first must be "" (no decision)')

    @property
    def statuses(self) -> np.ndarray:
        """(T, N) object: each decision's status, "" where the agent did not decide; spelt out
        from the codes at each call (a new array: writing into it changes nothing)."""
        return np.array(self.status_names, dtype=object)[self.status_codes]

    def __getstate__(self) -> dict[str, Any]:
        """Pickled with its arrays' contents; a spilled record's file mapping stays behind."""
        return {**self.__dict__, "spill": None, "cache": {}}

    def drop_resident(self) -> None:
        """Let go of the pages of a spilled record read so far (nothing for one in memory)."""
        if self.spill is not None:
            self.spill.drop()

    @property
    def dt(self) -> float:
        return float(self.scenario.dt)

    @property
    def steps(self) -> int:
        """Control steps simulated (the decisions of the agent that decided longest)."""
        return int(self.commands.shape[0])

    @property
    def n_agents(self) -> int:
        return int(self.positions.shape[1])

    @property
    def substeps(self) -> int:
        """Samples of the real trajectory per control step (1 without ``samples``)."""
        return 1 if self.samples is None else (self.samples.shape[0] - 1) // max(self.steps, 1)

    @property
    def track(self) -> tuple[np.ndarray, np.ndarray]:
        """The real trajectory the metrics judge: (times (S,), positions (S, N, 3)): the
        sub-step samples when recorded, else the steps."""
        if self.samples is None:
            return self.times, self.positions
        h = self.dt / self.substeps
        return np.arange(self.samples.shape[0]) * h, self.samples

    @property
    def ids(self) -> list[str]:
        return self.scenario.ids

    def arrival_times(self) -> np.ndarray:
        """Time (s) each agent first arrived, NaN when it never did."""
        out = np.full(self.n_agents, np.nan)
        first = np.argmax(self.arrived, axis=0)
        hit = self.arrived.any(axis=0)
        out[hit] = self.times[first[hit]]
        return out

    def same_trajectory(self, other: RunRecord) -> bool:
        """Bitwise-equal positions, velocities, commands and statuses (timing excluded)."""
        return (
            np.array_equal(self.positions, other.positions)
            and np.array_equal(self.velocities, other.velocities)
            and np.array_equal(self.commands, other.commands)
            and self._same_statuses(other)
            and np.array_equal(self.arrived, other.arrived)
        )

    def _same_statuses(self, other: RunRecord) -> bool:
        """Equal statuses, compared as codes into the union of both records' names."""
        if self.status_codes.shape != other.status_codes.shape:
            return False
        union = sorted(set(self.status_names) | set(other.status_names))
        mine = np.array([union.index(s) for s in self.status_names], dtype=np.int64)
        theirs = np.array([union.index(s) for s in other.status_names], dtype=np.int64)
        return np.array_equal(mine[self.status_codes], theirs[other.status_codes])


class RunBuffers:
    """The arrays a run fills step by step, [step, agent, ...] as in :class:`RunRecord`, for at
    most ``total`` steps of ``n`` agents. Memory is taken as the steps are filled (untouched
    pages of ``np.empty``/``np.zeros`` cost nothing), so a 10,000-agent run allotted
    ``max_time / dt`` steps that ends early costs only what it flew. ``same_commands``: the
    commands are the velocities (kinematic dynamics): one array for both. Statuses are kept as
    small codes, and the solve times only once they differ from the decision times.

    ``spill`` (:mod:`vo3d_opt.sim.spill`): keep the arrays in a temporary file (in
    ``spill_dir``) and let go of the steps written every ``DROP_EVERY`` steps; None: when the
    allotment exceeds ``SPILL_BYTES`` and the platform can (if the disk cannot hold it, or the
    directory is in memory, in memory with a warning). The sub-step samples of rotorpy runs
    stay in memory."""

    #: Steps between two ``Spill.drop`` calls of a spilled run.
    DROP_EVERY = 32

    def __init__(
        self,
        total: int,
        n: int,
        *,
        same_commands: bool = False,
        spill: bool | None = False,
        spill_dir: str | Path | None = None,
    ) -> None:
        f8, per_step = np.float64, (total, n)
        specs: dict[str, tuple[tuple[int, ...], Any]] = {
            "pos": ((total + 1, n, 3), f8),
            "vel": ((total, n, 3), f8),
            "pref": ((total, n, 3), f8),
            "decided": (per_step, np.bool_),
            "status_codes": (per_step, np.uint16),
            "dtimes": (per_step, f8),
            "stimes": (per_step, f8),
            "arrived": ((total + 1, n), np.bool_),
        }
        if not same_commands:
            specs["cmd"] = ((total, n, 3), f8)
        self.spill = _open_spill(specs, spill, spill_dir)
        a = self.spill.arrays if self.spill is not None else _in_memory(specs)
        self.pos, self.vel, self.pref = a["pos"], a["vel"], a["pref"]
        self.cmd = self.vel if same_commands else a["cmd"]
        self.decided, self.arrived = a["decided"], a["arrived"]
        self.status_codes = a["status_codes"]
        self.dtimes, self._stimes = a["dtimes"], a["stimes"]
        self.stimes: np.ndarray | None = None  # the decision times' until a step differs
        self.status_names: list[str] = [""]
        self.samples: np.ndarray | None = None
        self.sample_vel: np.ndarray | None = None

    def put_times(
        self, k: int, decision_times: np.ndarray, solve_times: np.ndarray, mask: np.ndarray
    ) -> None:
        """Row k of the decision and solve times, NaN where not ``mask``."""
        self.dtimes[k] = np.where(mask, decision_times, np.nan)
        if self.stimes is None and solve_times is decision_times:
            return
        solve = np.where(mask, solve_times, np.nan)
        if self.stimes is None:
            if np.array_equal(solve.view(np.uint64), self.dtimes[k].view(np.uint64)):
                return  # bit for bit the same
            self.stimes = self._stimes
            self.stimes[:k] = self.dtimes[:k]
            if self.spill is not None:
                self.spill.drop()
        self.stimes[k] = solve

    def release(self, k: int) -> None:
        """After step k: a spilled run lets go of the pages written so far, now and then."""
        if self.spill is not None and (k + 1) % self.DROP_EVERY == 0:
            self.spill.drop()

    def put_samples(
        self, k: int, sample_positions: np.ndarray, sample_velocities: np.ndarray
    ) -> None:
        """Step k's sub-step samples (S, N, 3) each, kept only when S > 1."""
        s = sample_positions.shape[0]
        if s < 2:
            return
        if self.samples is None:
            total, n = self.vel.shape[0], self.vel.shape[1]
            self.samples = np.empty((total * s + 1, n, 3))
            self.sample_vel = np.zeros((total * s + 1, n, 3))
            self.samples[0] = self.pos[0]
        assert self.sample_vel is not None  # allocated with self.samples
        self.samples[k * s + 1 : (k + 1) * s + 1] = sample_positions
        self.sample_vel[k * s + 1 : (k + 1) * s + 1] = sample_velocities

    def put_statuses(self, k: int, statuses: np.ndarray, mask: np.ndarray) -> None:
        """Row k of the statuses: ``statuses`` where ``mask``, "" elsewhere."""
        given = np.asarray(statuses)[mask]
        given = given.astype(str) if given.dtype == object else given
        names, codes = np.unique(given, return_inverse=True)
        lookup = np.empty(len(names), dtype=np.uint16)
        for c, name in enumerate(names):
            if name not in self.status_names:
                self.status_names.append(name)
            lookup[c] = self.status_names.index(name)
        self.status_codes[k, mask] = lookup[codes]

    def record(
        self,
        sc: Scenario,
        formulation: str,
        solver: str,
        steps: int,
        wall: float,
        extra: dict[str, Any] | None = None,
    ) -> RunRecord:
        s = steps
        return RunRecord(
            scenario=sc,
            formulation=formulation,
            solver=solver,
            times=np.arange(s + 1) * sc.dt,
            positions=self.pos[: s + 1],
            velocities=self.vel[:s],
            commands=self.cmd[:s],
            preferred=self.pref[:s],
            decided=self.decided[:s],
            status_codes=self.status_codes[:s],
            status_names=tuple(self.status_names),
            decision_times=self.dtimes[:s],
            solve_times=(self.dtimes if self.stimes is None else self.stimes)[:s],
            arrived=self.arrived[: s + 1],
            wall_time=wall,
            extra=extra or {},
            samples=self._cut(self.samples, s),
            sample_velocities=self._cut(self.sample_vel, s),
            spill=self.spill,
        )

    def _cut(self, arr: np.ndarray | None, steps: int) -> np.ndarray | None:
        if arr is None:
            return None
        per = (arr.shape[0] - 1) // self.vel.shape[0]
        return arr[: steps * per + 1]


def _in_memory(specs: dict[str, tuple[tuple[int, ...], Any]]) -> dict[str, np.ndarray]:
    """``specs``' arrays in anonymous memory (positions and times left uninitialised: every
    row a run reaches is written)."""
    lazy = {"pos", "dtimes", "stimes"}
    return {
        name: (np.empty if name in lazy else np.zeros)(shape, dtype=dtype)
        for name, (shape, dtype) in specs.items()
    }


def _open_spill(
    specs: dict[str, tuple[tuple[int, ...], Any]],
    spill: bool | None,
    directory: str | Path | None,
) -> Spill | None:
    """The temporary file of ``RunBuffers(spill=...)``, or None to keep the arrays in memory.
    ``spill=True`` or a ``directory`` given: any reason not to spill raises; ``spill=None``
    without one: a full disk or a directory in memory keeps the record in memory, warned."""
    if directory is not None and not os.path.isdir(directory):
        raise ValueError(f"spill_dir: {directory} is not a directory")
    if spill is not None and not spill:
        return None
    if not spill_supported():
        if spill:
            raise ValueError("spill: this platform cannot spill a record (Linux only)")
        return None
    if spill is None:
        if sum(array_bytes(shape, dtype) for shape, dtype in specs.values()) <= SPILL_BYTES:
            return None
    strict = bool(spill) or directory is not None
    where = spill_directory(directory)
    try:
        if in_memory_fs(where):
            fix = "choose one on disk" if directory is not None else "set TMPDIR to one on disk"
            raise ValueError(f"spill_dir: {where} is held in memory (tmpfs); {fix}")
        return Spill(specs, where)
    except (OSError, ValueError) as exc:
        if strict:
            raise
        warnings.warn(f"spill: kept in memory ({exc})", RuntimeWarning, stacklevel=4)
        return None


def scenario_dynamics(sc: Scenario) -> Dynamics:
    """The scenario's dynamics and wind (contract §5; ``velocity_response_tau`` is
    ``first_order``); the Dryden gusts are seeded with ``sensing.seed``."""
    return make_dynamics(sc.vehicle_dynamics, sc.wind, seed=sc.sensing.seed)


def scenario_goal_velocity(sc: Scenario) -> Callable[[np.ndarray], np.ndarray]:
    """The scenario's preferred-velocity rule as a function of the positions (N, 3), one per
    run (it keeps state): :func:`~vo3d_opt.sim.traffic.goal_velocity` towards each agent's goal,
    with :class:`~vo3d_opt.sim.traffic.GoalWithDetours`' way out of deadlocks."""
    return GoalWithDetours(sc.goals, sc.max_speed, float(sc.dt), near=sc.r_pz)


def _checked_commands(out: StepDecision, deciding: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The commands (0 for agents that do not decide) and statuses, a non-finite command
    replaced by 0 with the status ``invalid_velocity (...)``."""
    u = np.asarray(out.commands, dtype=float).reshape(deciding.shape[0], 3).copy()
    statuses = np.asarray(out.statuses)
    bad = deciding & ~np.all(np.isfinite(u), axis=1)
    if bad.any():
        statuses = statuses.astype(object)
        for i in np.flatnonzero(bad):
            statuses[i] = f"{INVALID} ({statuses[i]})"
    u[bad | ~deciding] = 0.0
    return u, statuses


#: Seconds a run goes before its progress bar shows (shorter runs show none).
PROGRESS_DELAY = 1.0


def _progress_bar(sc: Scenario, total: int, progress: bool | None) -> tqdm:
    """Steps against the most the run may take, with the arrivals alongside (when everyone
    arrived early, ``fly`` sets the total to the steps flown, so the bar ends at 100 %)."""
    return tqdm(
        total=total,
        desc=sc.name,
        unit="step",
        file=sys.stderr,
        delay=PROGRESS_DELAY,
        leave=False,
        dynamic_ncols=True,
        disable=(None if progress is None else not progress),
    )


def fly(
    sc: Scenario,
    step: DecisionStep,
    *,
    preferred_velocity: Callable[[np.ndarray], np.ndarray] | None = None,
    dynamics: Dynamics | None = None,
    progress: bool | None = None,
    max_steps: int | None = None,
    spill: bool | None = None,
    spill_dir: str | Path | None = None,
) -> RunRecord:
    """The one simulation loop (the module docstring): sense → ``step.decide`` → integrate,
    until every agent arrived or ``max_time`` (or ``max_steps``). ``preferred_velocity``:
    positions (N, 3) → preferred velocities (N, 3), default the scenario's goal rule;
    ``dynamics``: default :func:`scenario_dynamics`; ``progress`` None = a bar only on a TTY;
    ``spill``: keep the record in a temporary file in ``spill_dir`` (:class:`RunBuffers`; None:
    when its allotment exceeds ``vo3d_opt.sim.spill.SPILL_BYTES``; Linux only, never on a file
    system held in memory)."""
    n, dt, tol = sc.n_agents, float(sc.dt), sc.goal_tolerance
    straight = ~sc.avoids  # avoids: false: fly the preferred (goal) velocity, never decide
    total = sc.n_steps if max_steps is None else min(max_steps, sc.n_steps)
    prefer = preferred_velocity or scenario_goal_velocity(sc)
    dyn = dynamics or scenario_dynamics(sc)
    dyn.reset(sc.starts)
    buf = RunBuffers(
        total, n, same_commands=dyn.model == "kinematic", spill=spill, spill_dir=spill_dir
    )
    p, v = dyn.positions, dyn.velocities
    rate = derive_margins(sc).command_rate  # None: commands may change at once
    last = v  # the commands before: rate-limited models change them gradually from these
    done = np.linalg.norm(p - sc.goals, axis=1) <= tol
    dyn.hold(done)
    buf.pos[0], buf.arrived[0] = p, done
    steps = 0
    t_start = time.perf_counter()
    bar = _progress_bar(sc, total, progress)
    try:
        for k in range(total):
            if done.all():
                break
            steps = k + 1
            w = np.asarray(prefer(p), dtype=float)
            w[done] = 0.0
            deciding = ~done & ~straight
            waiting = getattr(prefer, "waiting", None)
            snap = Snapshot(
                k=k,
                t=k * dt,
                positions=p,
                velocities=v,
                preferred=w,
                deciding=deciding,
                waiting=None if waiting is None else waiting & deciding,
            )
            out = step.decide(snap)
            u, statuses = _checked_commands(out, deciding)
            u[straight] = w[straight]
            if rate is not None:  # the vehicle's command interface, whoever decided: RotorPy's
                u = within_reach(u, last, rate, dt, sc.max_speed)  # velocity loop (safety.py)
                u[done] = 0.0  # held in hover
                last = u
            buf.pref[k], buf.cmd[k], buf.decided[k] = w, u, deciding
            buf.put_statuses(k, statuses, deciding)
            buf.put_times(k, out.decision_times, out.solve_times, deciding)
            flown = dyn.step(u, dt)
            p = flown.positions
            buf.vel[k] = flown.velocities
            buf.put_samples(k, flown.sample_positions, flown.sample_velocities)
            arrived = ~done & (np.linalg.norm(p - sc.goals, axis=1) <= tol)
            done = done | arrived
            dyn.hold(arrived)  # an arrived agent hovers from now on: the others see it still
            v = dyn.velocities
            buf.pos[k + 1], buf.arrived[k + 1] = p, done
            buf.release(k)
            bar.update(1)
            bar.set_postfix_str(f"arrived {int(done.sum())}/{n}", refresh=False)
        if done.all() and bar.total != steps:  # everyone arrived before max_time: complete
            bar.total = steps
            shown = not bar.disable and bar.last_print_t >= bar.start_t + bar.delay
            if shown:  # a bar never shown is not drawn now: close() would leave it on screen
                bar.refresh()
    finally:
        bar.close()
    wall = time.perf_counter() - t_start
    return buf.record(sc, step.formulation, step.solver, steps, wall, step.extra())


def make_selector(
    formulation: str | None = None, solver: str | None = None, options: dict[str, Any] | None = None
) -> tuple[Any, str, str]:
    """Build ``vo3d_opt.selector.VelocitySelector``; returns (selector, formulation, solver).

    Unknown formulations or solvers raise ``ValueError`` (from the selector's constructor).
    """
    from vo3d_opt.selector import VelocitySelector  # late: the simulator works without it

    formulation = formulation or DEFAULT_FORMULATION
    kwargs: dict[str, Any] = dict(options or {})
    kwargs["formulation"] = formulation
    if solver is not None:
        kwargs["solver"] = solver
    sel = VelocitySelector(**kwargs)
    name = solver
    if name is None:  # the selector's choice; "none" when it uses no solver (sampled)
        value = getattr(sel, "solver", "default")
        name = value if isinstance(value, str) else "none"
    return sel, formulation, name


class Simulator:
    """Runs one scenario with one selector shared by every agent: a ``VelocitySelector`` (or
    anything with its ``select_many``) decides for the whole swarm in one call per step
    (:class:`~vo3d_opt.sim.deciders.SwarmSelect`); any other ``SelectorLike`` is called once per
    agent per step, in id order (:class:`~vo3d_opt.sim.deciders.PerAgentSelect`; it must be
    stateless between calls, or at least deterministic given the call order).
    ``max_neighbors`` (the k nearest vehicles in range) and ``threads`` go to ``select_many``.
    """

    def __init__(
        self,
        scenario: Scenario,
        selector: SelectorLike,
        *,
        formulation: str = "custom",
        solver: str = "custom",
        max_neighbors: int | None = None,
        threads: int | None = None,
    ) -> None:
        from vo3d_opt.sim.deciders import decision_step

        self.scenario = scenario
        self.selector = selector
        self.step = decision_step(
            scenario,
            selector,
            formulation=formulation,
            solver=solver,
            max_neighbors=max_neighbors,
            threads=threads,
        )

    def run(
        self,
        *,
        progress: bool | None = None,
        max_steps: int | None = None,
        spill: bool | None = None,
        spill_dir: str | Path | None = None,
    ) -> RunRecord:
        """Simulate until every agent arrived or ``max_time``; ``progress`` None = only on a
        TTY; ``spill``, ``spill_dir``: where the record lives (:func:`fly`)."""
        return fly(
            self.scenario,
            self.step,
            progress=progress,
            max_steps=max_steps,
            spill=spill,
            spill_dir=spill_dir,
        )


def scenario_selector(
    sc: Scenario, formulation: str | None = None, solver: str | None = None
) -> tuple[Any, str, str]:
    """The selector a scenario runs with: the given or the scenario's formulation and solver,
    configured by its ``selector_options`` (a preset, ``safe`` unless it names another, and
    fields over it) with ``sensing_range`` its vehicle sensing range. The simulator adds one
    thing of its own, from the scenario's physics: where the buffer ``vo3d_opt.sim.safety``
    derives (dynamics, noise, latency, a ``safety.pz_buffer``, agents slower than the limits)
    is not what the preset's ``buffer_steps`` gives each agent, it is passed in metres
    (``scenario_buffer``)."""
    options = {"sensing_range": float(sc.sensing.vehicle_range), **sc.selector_options}
    buffer = scenario_buffer(sc, options)
    if buffer is not None:
        options["pz_buffer"] = buffer
    return make_selector(formulation or sc.formulation, solver or sc.solver, options)


def flown_options(sc: Scenario) -> dict[str, Any]:
    """The selector options a run of ``sc`` flies with, as its summary reports them: the
    preset (``safe`` unless the scenario names another) and the fields set over it."""
    return {"preset": DEFAULT_PRESET, **sc.selector_options}


def scenario_buffer(sc: Scenario, options: dict[str, Any]) -> float | None:
    """The buffer (m) the scenario needs when the selector's own, ``buffer_steps`` steps of
    flight at each agent's top speed, is not it; None when it is (or ``pz_buffer`` is given)."""
    from vo3d_opt.config import SelectorConfig

    config = SelectorConfig.of(**options)
    if config.vo.pz_buffer is not None:
        return None
    steps = config.vo.buffer_steps
    derived = derive_margins(sc, steps).pz_buffer
    dt, top = float(sc.dt), np.minimum(sc.max_speed, sc.limits.v_max)
    own = {steps * float(v) * dt for v in top[sc.avoids]} or {derived}
    return None if own == {derived} else derived


def run_scenario(
    scenario: Scenario | str | Path,
    selector: SelectorLike | None = None,
    *,
    formulation: str | None = None,
    solver: str | None = None,
    progress: bool | None = None,
    max_steps: int | None = None,
    max_neighbors: int | None = None,
    threads: int | None = None,
    spill: bool | None = None,
    spill_dir: str | Path | None = None,
) -> RunRecord:
    """Load (if a path) and run a scenario. Without ``selector``, build a ``VelocitySelector``
    from ``formulation``/``solver`` (falling back to the scenario's, then to plane_qp and the
    selector's default solver); ``ValueError`` for unknown names. ``spill``, ``spill_dir``:
    where the record lives (:func:`fly`; None: in a temporary file when larger than
    ``SPILL_BYTES``)."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if selector is None:
        selector, formulation, solver = scenario_selector(sc, formulation, solver)
    sim = Simulator(
        sc,
        selector,
        formulation=formulation or "custom",
        solver=solver or "custom",
        max_neighbors=max_neighbors,
        threads=threads,
    )
    return sim.run(progress=progress, max_steps=max_steps, spill=spill, spill_dir=spill_dir)
