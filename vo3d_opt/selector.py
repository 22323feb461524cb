"""The public API: ``VelocitySelector(formulation, solver).select(...)`` (contracts §1) and
``select_many(...)`` for a whole swarm in one call (contracts §4).

With the default formulation and solver (``plane_qp`` on ``exact2d``) a decision is: validate
→ arrays → one call of the compiled core (``vo3d_opt._core``; the algorithm reads in
``vo3d_opt/algorithm/decide.hpp``) → ``Decision``. The other formulations and backends run the
Python formulations over the same compiled geometry.
Statuses: ``vo3d_opt.status.Status`` (documented in the README).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import swarm
from .config import SelectorConfig
from .extras import MissingExtra
from .formulations import cone_qp, kernel, nlp, plane_qp, sampled
from .formulations.common import (
    Bounds,
    Encounter,
    Options,
    Outcome,
    bounds_array,
    neighbor_rows,
    py_build_vos,
)
from .formulations.swarm import MANY_OUT_SIZE, decide_many
from .geometry.pyramid import prism_rows
from .solvers import (
    FEAS_TOL,
    NLP,
    QP,
    Backend,
    Result,
    available_qp_solvers,
    available_solvers,
    get_backend,
    standardise,
)
from .status import DECISION_STATUSES, Status
from .swarm import SwarmDecision
from .types import AgentState, Box, Cylinder, Limits, Neighbor, check_vector, positive_seconds

log = logging.getLogger(__name__)

FORMULATIONS = ("sampled", "plane_qp", "cone_qp", "nlp")
#: The default backend of each formulation: plane_qp's own exact solver (compiled, the whole
#: decision in one call); for cone_qp's 3D QPs the fastest outside backend
#: (benchmarks/bench_select.py); CasADi/IPOPT for nlp, started from plane_qp on exact2d.
DEFAULT_SOLVERS = {"plane_qp": "exact2d", "cone_qp": "daqp", "nlp": "casadi"}
DEFAULT_QP_SOLVER = DEFAULT_SOLVERS["plane_qp"]
DEFAULT_NLP_SOLVER = DEFAULT_SOLVERS["nlp"]


@dataclass
class Decision:
    """What ``select`` returns. ``velocity`` (3,) m/s world frame; ``solve_time`` s."""

    velocity: np.ndarray
    status: Status
    solve_time: float
    formulation: str
    solver: str | None
    plane: float | None = None  # phi (rad) of the avoidance plane chosen, when there is one
    info: dict = field(default_factory=dict)


def _vec3(value, name: str) -> np.ndarray:
    try:
        return check_vector(value, 3)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def _items(value, cls, name: str) -> list:
    items = [] if value is None else list(value)
    for i, item in enumerate(items):
        if not isinstance(item, cls):
            expected = " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
            raise ValueError(f"{name}[{i}]: expected {expected}, got {type(item).__name__}")
    return items


def _checked(backend: Backend, method: str):
    """Wrap a backend call: exceptions, and answers from outside backends that break the
    problem's own constraints, become "failed" results, so a misbehaving backend can never
    crash the control loop."""
    solve = getattr(backend, method)

    def call(problem: QP | NLP) -> Result:
        try:
            res = solve(problem)
        except Exception as exc:  # noqa: BLE001 - any backend error is a failed solve
            return Result(None, Status.FAILED, backend.name, f"{type(exc).__name__}: {exc}")
        if not isinstance(res, Result):
            return Result(None, Status.FAILED, backend.name, "backend returned no Result")
        if res.status == Status.OPTIMAL and not backend.checks_answers:
            qp = problem.qp if isinstance(problem, NLP) else problem
            x = None if res.x is None else np.asarray(res.x, dtype=float).reshape(-1)
            if (
                x is None
                or x.shape != (qp.n,)
                or not np.all(np.isfinite(x))
                or standardise(qp).violation(x) > FEAS_TOL
            ):
                return Result(None, Status.FAILED, res.solver, "garbage answer rejected")
            return Result(x, Status.OPTIMAL, res.solver, res.info)
        return res

    return call


def _select_many_compiled(
    groups: list[tuple[Options, np.ndarray]], inputs: swarm.SwarmInputs, threads: int, t0: float
) -> SwarmDecision:
    """``select_many`` compiled: every deciding vehicle, on ``threads`` threads; ``groups``:
    the options and the deciding vehicles (rows of ``who``) that plan with them."""
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
    result = _swarm_decision(
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


def _names(n: int, who: np.ndarray, names: np.ndarray) -> np.ndarray:
    """(n,) str: ``names`` (D,) at ``who``, "" elsewhere."""
    names = np.asarray(names, dtype=str)
    out = np.full(n, "", dtype=names.dtype if names.size else "<U1")
    out[who] = names
    return out


def _swarm_decision(
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


def _backend(name: str, formulation: str) -> Backend:
    """``get_backend(name)``; a solver library not installed is said with the formulation."""
    try:
        return get_backend(name)
    except MissingExtra as exc:
        raise exc.within(f"formulation {formulation!r}") from None


class VelocitySelector:
    """Chooses a safe velocity for one UAV per control period.

    ``formulation``: "sampled" (the paper's reference), "plane_qp" (default), "cone_qp", "nlp".
    ``solver``: a name from ``vo3d_opt.solvers.available_solvers()``; by default the
    formulation's entry of ``DEFAULT_SOLVERS`` (plane_qp: "exact2d", the compiled exact
    per-plane solver); "nlp" is started from plane_qp on ``start_solver`` (default exact2d).
    Keyword options (see ``Options``): plane_step_deg, heading_step_deg, speed_levels,
    polygon_sides, reciprocal, horizon, corrections, n_samples, qp_samples, pz_buffer (m: plan
    with every neighbour's sphere this much larger), margin, closing_guard (the speed towards
    each cooperative neighbour at most half the gap to its zone per dt), least_bad_escape (on
    by default: the least-bad fallback, when every velocity enters a zone at once, takes the
    one closing slowest on the zones the vehicle is inside; False: the one nearest the
    preferred velocity), fine_fallback (on by default: the fallbacks' grid at least the
    default one in a decision with an obstacle in reach or a non-cooperative neighbour).
    """

    def __init__(
        self,
        formulation: str = "plane_qp",
        solver: str | None = None,
        *,
        preset: str | None = None,
        start_solver: str | None = None,
        **overrides: Any,
    ) -> None:
        if formulation not in FORMULATIONS:
            raise ValueError(
                f"formulation: unknown {formulation!r}; available: {', '.join(FORMULATIONS)}"
            )
        #: The resolved configuration: the preset's values, each keyword over one field.
        self.config = SelectorConfig.of(preset, **overrides)
        self._resolved: dict[tuple[float, float, float | None], Options] = {}
        self.formulation = formulation
        self._qp = self._nlp = None
        self.solver: str | None = None
        if formulation == "sampled":
            if solver is not None:
                _backend(solver, formulation)  # a wrong name is still an error; sampled needs none
        elif formulation == "nlp":
            self.solver = solver or DEFAULT_NLP_SOLVER
            backend = _backend(self.solver, formulation)
            if backend.kind != "nlp":
                nlp_solvers = ", ".join(s for s in available_solvers() if s.startswith("casadi"))
                raise ValueError(
                    f"solver: formulation 'nlp' needs an NLP solver ({nlp_solvers}), got {solver!r}"
                )
            self._nlp = backend
            self._qp = self._qp_backend(start_solver or DEFAULT_QP_SOLVER, "plane_qp")
        else:
            self.solver = solver or DEFAULT_SOLVERS[formulation]
            self._qp = self._qp_backend(self.solver, formulation)
        #: The whole decision runs compiled: plane_qp (or nlp's start) on exact2d.
        self._compiled = self._qp is not None and self._qp.name == "exact2d"

    def options_for(self, v_max: float, dt: float, sensing_range: float | None = None) -> Options:
        """The numbers a decision with top speed ``v_max`` and period ``dt`` plans with
        (``SelectorConfig.resolve``), kept for the next decision with the same."""
        key = (v_max, dt, sensing_range) if self.config.per_decision else (0.0, 0.0, None)
        options = self._resolved.get(key)
        if options is None:
            if len(self._resolved) >= 64:
                self._resolved.clear()
            options = Options(**self.config.resolve(v_max, dt, sensing_range))
            self._resolved[key] = options
        return options

    @staticmethod
    def _qp_backend(name: str, formulation: str) -> Backend:
        backend = _backend(name, formulation)
        if backend.kind != "qp":
            raise ValueError(
                f"solver: {name!r} does not solve QPs; "
                f"available: {', '.join(available_qp_solvers())}"
            )
        if backend.name == "exact2d" and formulation != "plane_qp":
            raise ValueError(
                f"solver: 'exact2d' solves plane_qp's 2-variable problems only, "
                f"not {formulation}'s; "
                f"available: {', '.join(s for s in available_qp_solvers() if s != 'exact2d')}"
            )
        return backend

    # ------------------------------------------------------------------------------------------
    def select(
        self,
        own: AgentState,
        preferred_velocity: Sequence[float] | np.ndarray,
        neighbors: Sequence[Neighbor] = (),
        obstacles: Sequence[Cylinder | Box] = (),
        limits: Limits | None = None,
        dt: float = 0.2,
        *,
        sensing_range: float | None = None,
    ) -> Decision:
        """The velocity nearest ``preferred_velocity`` outside every VO within the limits.
        ``sensing_range`` (m): the range the neighbours were sensed within, which a horizon
        ``"sensing"`` (preset ``swarm``) is derived from when the configuration holds none."""
        t0 = time.perf_counter()
        if not isinstance(own, AgentState):
            raise ValueError(f"own: expected AgentState, got {type(own).__name__}")
        v_pref = _vec3(preferred_velocity, "preferred_velocity")
        nbrs = neighbor_rows(_items(neighbors, Neighbor, "neighbors"))
        obstacles = _items(obstacles, (Cylinder, Box), "obstacles")
        limits = Limits() if limits is None else limits
        if not isinstance(limits, Limits):
            raise ValueError(f"limits: expected Limits, got {type(limits).__name__}")
        dt = positive_seconds(dt, "dt")
        prisms = prism_rows(obstacles)
        options = self.options_for(limits.speed[1], dt, sensing_range)
        if self._compiled and self._nlp is None:
            return self._decide(
                own.position,
                own.velocity,
                v_pref,
                nbrs,
                prisms,
                bounds_array(limits, dt),
                options,
                t0,
            )
        bounds = Bounds.of(limits, dt)
        vos = py_build_vos(own.position, own.velocity, v_pref, nbrs, prisms, bounds, options.config)
        enc = Encounter(
            position=own.position,
            v_now=own.velocity,
            vos=vos,
            limits=limits,
            dt=float(dt),
            options=options,
            nbrs=nbrs,
        )
        out = self._run(enc, nbrs, prisms, bounds)
        status = out.status
        if status == Status.OPTIMAL and enc.inside_any:
            status = Status.INSIDE_PROTECTED_ZONE
        return Decision(
            velocity=kernel.enforce_limits(
                np.asarray(out.velocity, dtype=float), own.position, bounds
            ),
            status=status,
            solve_time=time.perf_counter() - t0,
            formulation=self.formulation,
            solver=self.solver,
            plane=out.plane,
            info=out.info,
        )

    def _decide(
        self,
        p: np.ndarray,
        v_now: np.ndarray,
        v_pref: np.ndarray,
        nbrs: np.ndarray,
        prisms: np.ndarray,
        limits: np.ndarray,
        options: Options,
        t0: float,
    ) -> Decision:
        """The compiled decision and its ``Decision``."""
        out = np.empty(kernel.OUT_SIZE)
        kernel.decide(p, v_now, v_pref, nbrs, prisms, limits, options.config, out)
        vx, vy, vz, status, phi, rnd, solved = out.tolist()
        return Decision(
            velocity=out[:3],
            status=DECISION_STATUSES[int(status)],
            solve_time=time.perf_counter() - t0,
            formulation=self.formulation,
            solver=self.solver,
            plane=None if math.isnan(phi) else phi,
            info={"round": kernel.ROUND_NAMES[int(rnd)], "solved": int(solved)},
        )

    # ------------------------------------------------------------------------------------------
    @property
    def compiled(self) -> bool:
        """Whether ``select_many`` runs as one compiled call (plane_qp on exact2d), not a loop."""
        return self._compiled and self._nlp is None

    def select_many(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        preferred_velocities: np.ndarray,
        r_pz: float | np.ndarray,
        obstacles: Sequence[Cylinder | Box] = (),
        limits: Limits | None = None,
        dt: float = 0.2,
        sensing_range: float = 55.0,
        max_neighbors: int | None = None,
        decide: np.ndarray | None = None,
        *,
        obstacle_range: float | None = None,
        spheres: np.ndarray | None = None,
        max_speed: float | np.ndarray | None = None,
        threads: int | None = None,
    ) -> SwarmDecision:
        """Decide for every vehicle of a swarm in one call (contracts §4): vehicle i gets exactly
        ``select``'s velocity and status with, as its ``Neighbor``s, the other vehicles within
        ``sensing_range`` (centre distance; with ``max_neighbors = k`` the k nearest of them)
        in index order, each with ``r_pz = max(r_pz[i], r_pz[j])``, cooperative when it decides
        too, and ``obstacles`` (all of them, for every vehicle). Vehicles with ``decide[i]``
        false keep their velocity (status "") and are seen by the others as non-cooperative.

        ``positions``, ``velocities``, ``preferred_velocities``: (N, 3); ``r_pz``: (N,) or one
        number, m; ``limits``: one ``Limits`` for all; ``decide``: (N,) bool or None (all).
        Extensions: ``obstacle_range`` (m; None: every obstacle): each vehicle takes only the
        obstacles (and spheres) whose surface is within this distance, found with a k-d tree;
        ``spheres`` (S, 5): x, y, z, radius, r_pz of static spheres, seen as zero-velocity,
        non-cooperative neighbours with their own r_pz after the vehicles; ``max_speed`` ((N,)
        or one number, m/s): each vehicle's own cap on ``limits``' v_max; ``threads``: threads
        for this call, at most the cores this process may use (default: all of them; the
        answers do not depend on it). Who senses whom: ``vo3d_opt.swarm``.

        With the default formulation and backend (plane_qp on exact2d) the deciding vehicles
        are decided by the compiled core in one call, parallel over vehicles on ``threads``
        threads, without a Python object per vehicle or neighbour. Any other formulation or
        backend (sampled, cone_qp, nlp, an outside QP solver) cannot run compiled: then
        ``select_many`` calls ``select`` for each deciding vehicle in turn, with the same
        neighbours, and returns the same.
        Malformed arrays raise ``ValueError`` naming the argument.
        """
        t0 = time.perf_counter()
        inputs = swarm.SwarmInputs.checked(
            positions,
            velocities,
            preferred_velocities,
            r_pz,
            obstacles,
            limits,
            dt,
            sensing_range,
            max_neighbors,
            decide,
            obstacle_range=obstacle_range,
            spheres=spheres,
            max_speed=max_speed,
        )
        n_threads = swarm.thread_count(threads)
        if not self.compiled:
            return self._select_many_loop(inputs, t0)
        return _select_many_compiled(self._options_by_vehicle(inputs), inputs, n_threads, t0)

    def _options_by_vehicle(self, inputs: swarm.SwarmInputs) -> list[tuple[Options, np.ndarray]]:
        """The deciding vehicles grouped by the options they plan with (their own top speed
        may set the buffer and the horizon): (options, the rows of ``who`` that use them)."""
        v_max = inputs.bounds[inputs.who, 1]
        groups = np.unique(v_max) if self.config.per_decision else v_max[:0]
        dt, rng = inputs.dt, inputs.sensing_range
        if groups.size <= 1:
            top = float(groups[0]) if groups.size else inputs.limits.v_max
            return [(self.options_for(top, dt, rng), np.arange(inputs.who.shape[0]))]
        return [(self.options_for(float(v), dt, rng), np.flatnonzero(v_max == v)) for v in groups]

    def _select_many_loop(self, inputs: swarm.SwarmInputs, t0: float) -> SwarmDecision:
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
            dec = self.select(
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
        result = _swarm_decision(
            V, who, vel, statuses.astype(str), rounds.astype(str), planes, counts, solved
        )
        result.times[who] = times
        result.solve_time = time.perf_counter() - t0
        return result

    def _run(self, enc: Encounter, nbrs: np.ndarray, prisms: np.ndarray, bounds: Bounds) -> Outcome:
        if self.formulation == "sampled":
            return sampled.select(enc)
        # The preferred velocity itself, when safe, is every formulation's optimum.
        if not enc.inside_any and enc.within_limits(enc.v_pref)[0] and not enc.pref_in.any():
            return Outcome(enc.v_pref.copy(), Status.OPTIMAL, None, {"round": "preferred"})
        assert self._qp is not None  # every formulation but sampled has a QP backend
        solve = _checked(self._qp, "solve")
        if self.formulation == "cone_qp":
            return cone_qp.select(enc, solve, self._qp.has_cones)
        start = self._plane_qp(enc, nbrs, prisms, bounds, solve)
        if self.formulation == "plane_qp":
            return start
        assert self._nlp is not None  # set for formulation "nlp"
        return nlp.select(enc, start, _checked(self._nlp, "solve_nlp"))

    def _plane_qp(
        self, enc: Encounter, nbrs: np.ndarray, prisms: np.ndarray, bounds: Bounds, solve
    ) -> Outcome:
        if not self._compiled:
            assert self._qp is not None  # plane_qp and nlp have a QP backend
            return plane_qp.select(enc, solve, self._qp.has_cones)
        d = self._decide(
            enc.position,
            enc.v_now,
            enc.v_pref,
            nbrs,
            prisms,
            bounds_array(enc.limits, enc.dt),
            enc.options,
            0.0,
        )
        status = Status.OPTIMAL if d.status == Status.INSIDE_PROTECTED_ZONE else d.status
        return Outcome(d.velocity, status, d.plane, d.info)


__all__ = [
    "Decision",
    "SwarmDecision",
    "VelocitySelector",
    "DEFAULT_SOLVERS",
    "FORMULATIONS",
]
