"""The public API: ``VelocitySelector(formulation, solver).select(...)`` (contracts §1).

With the default formulation and solver (``plane_qp`` on ``exact2d``) a decision is: validate
→ arrays → one compiled call (``formulations/kernel.py``) → ``Decision``. The other
formulations and backends run the Python formulations over the same compiled geometry.
Statuses: ``vo3d_opt.status.Status`` (documented in the README).
"""
from __future__ import annotations

import logging
import math
import numbers
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .formulations import cone_qp, kernel, nlp, plane_qp, sampled
from .formulations.common import Bounds, Encounter, Options, Outcome, bounds_array, neighbor_rows, py_build_vos
from .geometry.pyramid import prism_rows
from .solvers import FEAS_TOL, NLP, QP, Backend, Result, available_qp_solvers, available_solvers, get_backend, standardise
from .status import DECISION_STATUSES, Status
from .types import AgentState, Box, Cylinder, Limits, Neighbor, check_vector

log = logging.getLogger(__name__)

FORMULATIONS = ("sampled", "plane_qp", "cone_qp", "nlp")
#: The default backend of each formulation: plane_qp's own exact solver (compiled, the whole
#: decision in one call); for cone_qp's 3D QPs the fastest outside backend
#: (benchmarks/bench_select.py); CasADi/IPOPT for nlp, started from plane_qp on exact2d.
DEFAULT_SOLVERS = {"plane_qp": "exact2d", "cone_qp": "daqp", "nlp": "casadi"}
DEFAULT_QP_SOLVER = DEFAULT_SOLVERS["plane_qp"]
DEFAULT_NLP_SOLVER = DEFAULT_SOLVERS["nlp"]
#: Seconds a first compilation may take before the user is told about it on stderr.
_COMPILE_NOTICE_AFTER = 3.0
_warm_lock = threading.Lock()
_warm = False


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
            if x is None or x.shape != (qp.n,) or not np.all(np.isfinite(x)) or standardise(qp).violation(x) > FEAS_TOL:
                return Result(None, Status.FAILED, res.solver, "garbage answer rejected")
            return Result(x, Status.OPTIMAL, res.solver, res.info)
        return res

    return call


def warm_up() -> None:
    """Compile the decision kernel, or load it from numba's on-disk cache, once per process,
    saying on stderr when that takes a while (a first run on a machine compiles it). Called by
    the selector's constructor, so that no reported time includes it."""
    global _warm
    with _warm_lock:
        if _warm:
            return
        shown = threading.Event()

        def tell() -> None:
            log.warning("vo3d-opt: compiling the decision kernel (once per machine; numba caches it on disk)...")
            shown.set()

        notice = threading.Timer(_COMPILE_NOTICE_AFTER, tell)
        notice.daemon = True
        notice.start()
        t0 = time.perf_counter()
        try:
            own = AgentState(position=(0.0, 0.0, 10.0), velocity=(1.0, 0.0, 0.0))
            nbrs = neighbor_rows([Neighbor(position=(10.0, 0.0, 10.0), velocity=(-1.0, 0.0, 0.0), r_pz=3.0)])
            kernel.decide(own.position, own.velocity, check_vector((1.0, 0.0, 0.0), 3), nbrs, np.zeros((0, 4)),
                          bounds_array(Limits(), 0.2), *Options().packed, np.empty(kernel.OUT_SIZE))
        finally:
            notice.cancel()
        if shown.is_set():
            log.warning("vo3d-opt: the decision kernel is ready (%.0f s)", time.perf_counter() - t0)
        _warm = True


class VelocitySelector:
    """Chooses a safe velocity for one UAV per control period.

    ``formulation``: "sampled" (the paper's reference), "plane_qp" (default), "cone_qp", "nlp".
    ``solver``: a name from ``vo3d_opt.solvers.available_solvers()``; by default the
    formulation's entry of ``DEFAULT_SOLVERS`` (plane_qp: "exact2d", the compiled exact
    per-plane solver); "nlp" is started from plane_qp on ``start_solver`` (default exact2d).
    Keyword options (see ``Options``): plane_step_deg, heading_step_deg, speed_levels,
    polygon_sides, reciprocal, horizon, corrections, n_samples, qp_samples, pz_buffer (m: plan
    with every neighbour's sphere this much larger), margin.
    """

    def __init__(self, formulation: str = "plane_qp", solver: str | None = None, *,
                 start_solver: str | None = None, **options) -> None:
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation: unknown {formulation!r}; available: {', '.join(FORMULATIONS)}")
        self.options = Options(**options)  # ValueError naming a wrong or unknown option
        self.formulation = formulation
        self._qp = self._nlp = None
        self.solver: str | None = None
        if formulation == "sampled":
            if solver is not None:
                get_backend(solver)  # a wrong name is still an error; sampled needs no solver
        elif formulation == "nlp":
            self.solver = solver or DEFAULT_NLP_SOLVER
            backend = get_backend(self.solver)
            if backend.kind != "nlp":
                raise ValueError(f"solver: formulation 'nlp' needs an NLP solver "
                                 f"({', '.join(s for s in available_solvers() if s.startswith('casadi'))}), got {solver!r}")
            self._nlp = backend
            self._qp = self._qp_backend(start_solver or DEFAULT_QP_SOLVER, "plane_qp")
        else:
            self.solver = solver or DEFAULT_SOLVERS[formulation]
            self._qp = self._qp_backend(self.solver, formulation)
        #: The whole decision runs compiled: plane_qp (or nlp's start) on exact2d.
        self._compiled = self._qp is not None and self._qp.name == "exact2d"
        if self._compiled:
            warm_up()

    @staticmethod
    def _qp_backend(name: str, formulation: str) -> Backend:
        backend = get_backend(name)
        if backend.kind != "qp":
            raise ValueError(f"solver: {name!r} does not solve QPs; available: {', '.join(available_qp_solvers())}")
        if backend.name == "exact2d" and formulation != "plane_qp":
            raise ValueError(f"solver: 'exact2d' solves plane_qp's 2-variable problems only, not {formulation}'s; "
                             f"available: {', '.join(s for s in available_qp_solvers() if s != 'exact2d')}")
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
    ) -> Decision:
        """The velocity nearest ``preferred_velocity`` outside every VO within the limits."""
        t0 = time.perf_counter()
        if not isinstance(own, AgentState):
            raise ValueError(f"own: expected AgentState, got {type(own).__name__}")
        v_pref = _vec3(preferred_velocity, "preferred_velocity")
        nbrs = neighbor_rows(_items(neighbors, Neighbor, "neighbors"))
        obstacles = _items(obstacles, (Cylinder, Box), "obstacles")
        limits = Limits() if limits is None else limits
        if not isinstance(limits, Limits):
            raise ValueError(f"limits: expected Limits, got {type(limits).__name__}")
        if isinstance(dt, bool) or not (isinstance(dt, numbers.Real) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt: must be a positive finite number of seconds, got {dt!r}")
        prisms = prism_rows(obstacles)
        if self._compiled and self._nlp is None:
            return self._decide(own.position, own.velocity, v_pref, nbrs, prisms, bounds_array(limits, dt), t0)
        bounds = Bounds.of(limits, dt)
        vos = py_build_vos(own.position, own.velocity, v_pref, nbrs, prisms, bounds, self.options.config)
        enc = Encounter(position=own.position, v_now=own.velocity, vos=vos, limits=limits, dt=float(dt),
                        options=self.options)
        out = self._run(enc, nbrs, prisms, bounds)
        status = out.status
        if status == Status.OPTIMAL and enc.inside_any:
            status = Status.INSIDE_PROTECTED_ZONE
        return Decision(velocity=kernel.enforce_limits(np.asarray(out.velocity, dtype=float), own.position, bounds),
                        status=status, solve_time=time.perf_counter() - t0, formulation=self.formulation,
                        solver=self.solver, plane=out.plane, info=out.info)

    def _decide(self, p: np.ndarray, v_now: np.ndarray, v_pref: np.ndarray, nbrs: np.ndarray, prisms: np.ndarray,
                limits: np.ndarray, t0: float) -> Decision:
        """The compiled decision and its ``Decision``."""
        out = np.empty(kernel.OUT_SIZE)
        kernel.decide(p, v_now, v_pref, nbrs, prisms, limits, *self.options.packed, out)
        vx, vy, vz, status, phi, rnd, solved = out.tolist()
        return Decision(velocity=out[:3], status=DECISION_STATUSES[int(status)], solve_time=time.perf_counter() - t0,
                        formulation=self.formulation, solver=self.solver, plane=None if math.isnan(phi) else phi,
                        info={"round": kernel.ROUND_NAMES[int(rnd)], "solved": int(solved)})

    def _run(self, enc: Encounter, nbrs: np.ndarray, prisms: np.ndarray, bounds: Bounds) -> Outcome:
        if self.formulation == "sampled":
            return sampled.select(enc)
        # The preferred velocity itself, when safe, is every formulation's optimum.
        if not enc.inside_any and enc.within_limits(enc.v_pref)[0] and not enc.pref_in.any():
            return Outcome(enc.v_pref.copy(), Status.OPTIMAL, None, {"round": "preferred"})
        solve = _checked(self._qp, "solve")
        if self.formulation == "cone_qp":
            return cone_qp.select(enc, solve, self._qp.has_cones)
        start = self._plane_qp(enc, nbrs, prisms, bounds, solve)
        if self.formulation == "plane_qp":
            return start
        return nlp.select(enc, start, _checked(self._nlp, "solve_nlp"))

    def _plane_qp(self, enc: Encounter, nbrs: np.ndarray, prisms: np.ndarray, bounds: Bounds, solve) -> Outcome:
        if not self._compiled:
            return plane_qp.select(enc, solve, self._qp.has_cones)
        d = self._decide(enc.position, enc.v_now, enc.v_pref, nbrs, prisms, bounds_array(enc.limits, enc.dt), 0.0)
        status = Status.OPTIMAL if d.status == Status.INSIDE_PROTECTED_ZONE else d.status
        return Outcome(d.velocity, status, d.plane, d.info)


__all__ = ["Decision", "VelocitySelector", "DEFAULT_SOLVERS", "FORMULATIONS", "warm_up"]
