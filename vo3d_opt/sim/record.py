"""What a simulation step exchanges and what a run leaves: the snapshot a decision step
senses, its answer, the protocols of a selector and of a decision step, and the run's record
(:class:`RunRecord`, filled step by step through :class:`RunBuffers`, in memory or spilled to a
temporary file: :mod:`vo3d_opt.sim.spill`)."""

from __future__ import annotations

import os
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from vo3d_opt.sim.scenario import Scenario
from vo3d_opt.sim.spill import (
    SPILL_BYTES,
    Spill,
    array_bytes,
    in_memory_fs,
    spill_directory,
    spill_supported,
)
from vo3d_opt.types import AgentState, Limits, Neighbor


class DecisionLike(Protocol):
    velocity: Any
    status: str
    solve_time: float


class SelectorLike(Protocol):
    """Anything with ``VelocitySelector.select``'s signature."""

    def select(
        self,
        *,
        own: AgentState,
        preferred_velocity: Any,
        neighbors: list[Neighbor],
        obstacles: list[Any],
        limits: Limits,
        dt: float,
    ) -> DecisionLike: ...


@dataclass(frozen=True)
class Snapshot:
    """What the agents sense at step ``k`` (time ``t``): everyone's ``positions`` and
    ``velocities`` (N, 3), their ``preferred`` velocities (N, 3; 0 for arrived agents that hover)
    and which of them decide (``deciding`` (N,): those that have not arrived, and arrived ones
    keeping watch, ``traffic.keep_watch``); ``waiting`` (N,) the agents not yet arrived that
    stalled at their goal's door, when the preferred-velocity rule says
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

    ``positions[k]`` is the state at ``times[k]`` (k = 0..T); ``commands[k]`` the decision taken at
    ``times[k]`` and ``velocities[k]`` the velocity flown over [t_k, t_k+1] (under kinematic
    dynamics the command itself: then ``commands`` is the same array as ``velocities``; 0 for
    arrived agents that hover). ``arrived[k, i]``: agent i has reached its goal by ``times[k]`` and,
    if it keeps watch, is within ``goal_tolerance`` of it. ``decided[k, i]`` says whether agent i
    decided at step k; ``statuses``, ``decision_times`` (wall time of its decision, s: the
    ``select()`` call, or its equal share of the step's ``select_many()`` or ``doStep()`` call) and
    ``solve_times`` (the decision's own ``solve_time``; the same array as ``decision_times`` when
    every step said the same) are "" / NaN where it did not. The statuses are kept as
    ``status_codes`` (T, N) into ``status_names`` (whose first is "", no decision); ``statuses``
    spells them out (an object array, built at each call).

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


def record_specs(
    total: int, n: int, same_commands: bool = False
) -> dict[str, tuple[tuple[int, ...], Any]]:
    """(shape, dtype) of each array a run of ``total`` steps of ``n`` agents fills."""
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
    return specs


def machine_capacity(spill_dir: str | Path | None = None) -> int:
    """Bytes this machine can hold a record in: its memory and the free disk where a record
    would spill (a best guess: 0 for what cannot be read)."""
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        memory = 0
    try:
        disk = shutil.disk_usage(spill_directory(spill_dir)).free
    except (OSError, ValueError):
        disk = 0
    return int(memory + disk)


def check_allotment(
    total: int, n: int, same_commands: bool = False, spill_dir: str | Path | None = None
) -> None:
    """``ValueError`` naming ``max_time`` when a run of ``total`` steps of ``n`` agents could
    fill more than :func:`machine_capacity`: refused before anything is reserved."""
    need = sum(
        array_bytes(shape, dtype) for shape, dtype in record_specs(total, n, same_commands).values()
    )
    have = machine_capacity(spill_dir)
    if need > have:
        raise ValueError(
            f"max_time: the run may take {total:,} steps of {n:,} agents, a record of "
            f"{need / 2**30:,.1f} GiB, more than this machine can hold ({have / 2**30:,.1f} GiB "
            "of memory and free disk); shorten max_time or lengthen dt"
        )


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
        specs = record_specs(total, n, same_commands)
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
