"""The public API: ``VelocitySelector(formulation, solver).select(...)`` for one vehicle,
``select_arrays(...)`` for the same from numpy arrays, and ``select_many(...)`` for a whole
swarm in one call.

With the default formulation and solver (``plane_qp`` on ``exact2d``) a decision is: the inputs
checked (``formulations.inputs``) → one call of the compiled core (``vo3d_opt._core``; the
algorithm reads in ``vo3d_opt/algorithm/decide.hpp``) → ``Decision``; inputs of the plain kind
(lists of the user's objects or float64 arrays, a float dt) are checked, decided and answered
in that one call (``kernel.object_path``), with the same answer. The other formulations
and backends run on the Python path (``formulations.outside``) over the same compiled geometry;
``select_many`` is ``vo3d_opt.swarm``. Statuses: ``vo3d_opt.status.Status`` (documented in
docs/guide/statuses.md).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .config import SelectorConfig, turns_at_once
from .formulations import inputs, kernel
from .formulations.common import Bounds, Encounter, Options, planning_options, py_build_vos
from .formulations.outside import PythonPath, backend_for, qp_backend
from .formulations.sampled import check_grid
from .geometry.pyramid import PRISM_WIDTH
from .solvers import available_solvers
from .status import Status
from .swarm import SwarmDecision, SwarmInputs, thread_count
from .swarm.checks import distance
from .swarm.many import options_by_vehicle, select_many_compiled, select_many_loop
from .types import AgentState, Box, Cylinder, Limits, Neighbor

log = logging.getLogger(__name__)

FORMULATIONS = ("sampled", "plane_qp", "cone_qp", "nlp")
#: The default backend of each formulation: plane_qp's own exact solver (compiled, the whole
#: decision in one call); for cone_qp's 3D QPs the fastest outside backend
#: (benchmarks/bench_select.py); CasADi/IPOPT for nlp, started from plane_qp on exact2d.
DEFAULT_SOLVERS = {"plane_qp": "exact2d", "cone_qp": "daqp", "nlp": "casadi"}
DEFAULT_QP_SOLVER = DEFAULT_SOLVERS["plane_qp"]
DEFAULT_NLP_SOLVER = DEFAULT_SOLVERS["nlp"]
_clock = time.perf_counter


def _sensing_range(value: Any) -> float | None:
    """None, or a positive number of metres (inf: no horizon): a horizon derived from a NaN
    or negative range would be none at all, or an error naming ``horizon``."""
    return None if value is None else distance(value, "sensing_range", allow_inf=True)


@dataclass(slots=True)
class Decision:
    """What ``select`` returns. ``velocity`` (3,) m/s world frame; ``solve_time`` s."""

    velocity: np.ndarray
    status: Status
    solve_time: float
    formulation: str
    solver: str | None
    plane: float | None = None  # phi (rad) of the avoidance plane chosen, when there is one
    info: dict = field(default_factory=dict)


class VelocitySelector:
    """Chooses a safe velocity for one UAV per control period.

    ``formulation``: "sampled" (the paper's reference), "plane_qp" (default), "cone_qp", "nlp".
    ``solver``: a name from ``vo3d_opt.solvers.available_solvers()``; by default the
    formulation's entry of ``DEFAULT_SOLVERS`` (plane_qp: "exact2d", the compiled exact
    per-plane solver); "nlp" is started from plane_qp on ``start_solver`` (default exact2d).
    ``preset``: "safe" (default), "paper", "fast" or "swarm"; keyword options: any field of
    ``SelectorConfig`` over the preset's (the options table of the presets guide): among them
    ``reciprocal``, ``horizon``, ``obstacle_horizon``, ``sensing_range``, ``buffer_steps``,
    ``pz_buffer``, ``margin``, ``closing_guard``, ``least_bad_escape``, the planes and grids
    (``plane_step_deg``, ``qp_samples``, ``heading_step_deg``, ``speed_levels``,
    ``fallback_heading_step_deg``, ``fallback_speed_levels``) and the rules that refine them
    near an obstacle or a vehicle that does not avoid (``fine_planes``, ``fine_fallback``). An
    unknown option or a value out of range is a ``ValueError`` naming it.
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
        self._resolved: dict[tuple[float, float, float | None, bool], Options] = {}
        # The last decision's limits, dt and sensing range, and their bounds and Config: a
        # control loop asks with the same ones every time.
        self._last: tuple[Any, ...] = (None, None, None, None, None)
        self.formulation = formulation
        self.solver: str | None = None
        qp = nlp = None
        if formulation == "sampled":
            check_grid(self.config)
            if solver is not None:
                # a wrong name is still an error; sampled needs no solver
                backend_for(solver, formulation)
        elif formulation == "nlp":
            self.solver = solver or DEFAULT_NLP_SOLVER
            nlp = backend_for(self.solver, formulation)
            if nlp.kind != "nlp":
                nlp_solvers = ", ".join(s for s in available_solvers() if s.startswith("casadi"))
                raise ValueError(
                    f"solver: formulation 'nlp' needs an NLP solver ({nlp_solvers}), got {solver!r}"
                )
            qp = qp_backend(start_solver or DEFAULT_QP_SOLVER, "plane_qp")
        else:
            self.solver = solver or DEFAULT_SOLVERS[formulation]
            qp = qp_backend(self.solver, formulation)
        #: The Python path (None: the whole decision runs compiled, plane_qp on exact2d).
        self._python = (
            None
            if formulation == "plane_qp" and qp is not None and qp.name == "exact2d"
            else PythonPath(formulation, qp, nlp)
        )
        #: select() in one compiled call for inputs of the plain kind (None: the Python path).
        self._objects = None if self._python else kernel.object_path(Decision, self, _clock)

    def options_for(
        self,
        v_max: float,
        dt: float,
        sensing_range: float | None = None,
        acceleration: float | None = None,
    ) -> Options:
        """The numbers a decision with top speed ``v_max``, period ``dt`` and acceleration
        limit ``acceleration`` plans with (``SelectorConfig.resolve``), kept for the next
        decision with the same."""
        at_once = turns_at_once(v_max, dt, acceleration)  # all that resolve reads of it
        per = self.config.per_decision
        key = (v_max, dt, sensing_range, at_once) if per else (0.0, 0.0, None, True)
        options = self._resolved.get(key)
        if options is None:
            if len(self._resolved) >= 64:
                self._resolved.clear()
            options = Options(**self.config.resolve(v_max, dt, sensing_range, acceleration))
            self._resolved[key] = options
        return options

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
        ``"sensing"`` (preset ``swarm``; none under a ``limits.acceleration`` with
        ``a dt < 2 v_max``) is derived from when the configuration holds none;
        positive, at most 1e7 or inf (no horizon), else a ``ValueError`` naming it."""
        t0 = _clock()
        fast = self._objects if sensing_range is None else None
        if fast and (
            d := fast.decide(own, preferred_velocity, neighbors, obstacles, limits, dt, t0)
        ):
            return d  # the inputs of the plain kind, checked and decided in one compiled call
        own = inputs.agent(own)
        v_pref = inputs.vector3(preferred_velocity, "preferred_velocity")
        nbrs = inputs.neighbor_tuples(neighbors)
        prisms = inputs.prism_tuples(obstacles)
        limits = inputs.limits_of(limits)
        dt = inputs.period(dt)
        sensing_range = _sensing_range(sensing_range)
        p, v_now = own.position, own.velocity
        if self._python is None:
            return self._compiled(p, v_now, v_pref, nbrs, prisms, limits, dt, sensing_range, t0)
        rows = np.array(nbrs, dtype=float).reshape(-1, 8)
        table = np.array(prisms, dtype=float).reshape(-1, PRISM_WIDTH)
        v = np.asarray(v_pref, dtype=float)
        return self._select_python(p, v_now, v, rows, table, limits, dt, sensing_range, t0)

    def select_arrays(
        self,
        position: np.ndarray,
        velocity: np.ndarray,
        preferred_velocity: np.ndarray,
        neighbors: np.ndarray | None = None,
        obstacles: np.ndarray | Sequence[Cylinder | Box] | None = None,
        limits: Limits | None = None,
        dt: float = 0.2,
        *,
        cooperative: np.ndarray | None = None,
        sensing_range: float | None = None,
    ) -> Decision:
        """``select`` for a control loop that holds its state as numpy arrays: the same answer
        as ``select`` with the same numbers, bit for bit, without a Python object per
        neighbour.

        ``position``, ``velocity``, ``preferred_velocity``: (3,) m, m/s (the own vehicle's
        ``AgentState`` and the preferred velocity); ``neighbors``: (N, 7) px, py, pz, vx, vy,
        vz, r_pz, one row per ``Neighbor`` (None: none); ``cooperative``: (N,) booleans, each
        neighbour's ``Neighbor.cooperative`` (None: all True); ``obstacles``: (M, 6) prism rows
        (``Cylinder.prism``: x, y, L_pz, h_pz, the obstacle's height and rim; (M, 4): no
        roof), or the ``Cylinder`` and ``Box`` objects themselves (None: none); ``limits``, ``dt``,
        ``sensing_range``: as for ``select``. Real numbers only, finite, at most 1e7 in
        magnitude, r_pz, L_pz, h_pz, height and rim positive: anything else is a
        ``ValueError`` naming the argument, and for an array the row and the column.
        """
        t0 = _clock()
        fast = self._objects if sensing_range is None else None
        vectors = (position, velocity, preferred_velocity)
        if fast and (
            d := fast.decide_arrays(*vectors, neighbors, cooperative, obstacles, limits, dt, t0)
        ):
            return d  # float64 arrays of the usual shapes: checked and decided in one call
        p = inputs.array_vector(position, "position")
        v_now = inputs.array_vector(velocity, "velocity")
        v_pref = inputs.array_vector(preferred_velocity, "preferred_velocity")
        nbrs = inputs.neighbor_array(neighbors, cooperative)
        prisms = inputs.prism_array(obstacles)
        limits = inputs.limits_of(limits)
        dt = inputs.period(dt)
        sensing_range = _sensing_range(sensing_range)
        if self._python is None:
            return self._compiled(p, v_now, v_pref, nbrs, prisms, limits, dt, sensing_range, t0)
        return self._select_python(p, v_now, v_pref, nbrs, prisms, limits, dt, sensing_range, t0)

    def _compiled(
        self,
        p: np.ndarray,
        v_now: np.ndarray,
        v_pref: inputs.Vector3,
        nbrs: list[inputs.Row] | np.ndarray,
        prisms: list[inputs.Row] | np.ndarray,
        limits: Limits,
        dt: float,
        sensing_range: float | None,
        t0: float,
    ) -> Decision:
        """The compiled decision (``kernel.decide_rows``: the rows as tuples or arrays)."""
        bounds, config = self._bounds_and_config(limits, dt, sensing_range)
        out = np.empty(kernel.OUT_SIZE)
        kernel.decide_rows(p, v_now, v_pref, nbrs, prisms, bounds, config, out)
        return kernel.answer(out, t0, Decision, self, _clock)

    def _bounds_and_config(
        self, limits: Limits, dt: float, sensing_range: float | None
    ) -> tuple[tuple[float, ...], Any]:
        """The decision's bounds (``inputs.bounds_row``) and the Config it plans with."""
        last = self._last
        if last[0] is limits and last[1] == dt and last[2] == sensing_range:
            return last[3], last[4]
        bounds = inputs.bounds_row(limits, dt)
        config = self.options_for(limits.speed[1], dt, sensing_range, limits.acceleration).config
        self._last = (limits, dt, sensing_range, bounds, config)
        return bounds, config

    def _select_python(
        self,
        p: np.ndarray,
        v_now: np.ndarray,
        v_pref: np.ndarray,
        nbrs: np.ndarray,
        prisms: np.ndarray,
        limits: Limits,
        dt: float,
        sensing_range: float | None,
        t0: float,
    ) -> Decision:
        """A decision on the Python path: the VOs (compiled), the formulation's answer, the
        last line of the contract."""
        assert self._python is not None
        options = self.options_for(limits.speed[1], dt, sensing_range, limits.acceleration)
        bounds = Bounds.of(limits, dt)
        vos = py_build_vos(p, v_now, v_pref, nbrs, prisms, bounds, options.config)
        enc = Encounter(
            position=p,
            v_now=v_now,
            vos=vos,
            limits=limits,
            dt=dt,
            options=planning_options(options, vos, nbrs),
            nbrs=nbrs,
        )
        out = self._python.run(enc, prisms)
        status = out.status
        if status == Status.OPTIMAL and enc.inside_any:
            status = Status.INSIDE_PROTECTED_ZONE
        return Decision(
            velocity=kernel.enforce_limits(np.asarray(out.velocity, dtype=float), p, bounds),
            status=status,
            solve_time=time.perf_counter() - t0,
            formulation=self.formulation,
            solver=self.solver,
            plane=out.plane,
            info=out.info,
        )

    # ------------------------------------------------------------------------------------------
    @property
    def compiled(self) -> bool:
        """Whether ``select_many`` runs as one compiled call (plane_qp on exact2d), not a loop."""
        return self._python is None

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
        """Decide for every vehicle of a swarm in one call: vehicle i gets exactly
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
        args = SwarmInputs.checked(
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
        n_threads = thread_count(threads)
        if not self.compiled:
            return select_many_loop(self.select, args, t0)
        groups = options_by_vehicle(args, self.options_for, self.config.per_decision)
        return select_many_compiled(groups, args, n_threads, t0)


__all__ = [
    "Decision",
    "SwarmDecision",
    "VelocitySelector",
    "DEFAULT_SOLVERS",
    "FORMULATIONS",
]
