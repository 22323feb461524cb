"""The public API: ``VelocitySelector(formulation, solver).select(...)`` (contracts §1).

Statuses (documented in the README):

- ``optimal``: a velocity outside every VO (exact 3D check) and within the limits;
- ``inside_protected_zone``: A is already inside a protected zone; the velocity is the best
  escape found (not closing on any zone it is inside, outside the other VOs when possible);
- ``infeasible_min_violation``: no velocity within the limits is outside every VO; the one whose
  first protected-zone intrusion comes latest is returned;
- ``solver_failed_fallback``: the backend failed (or returned garbage) on every problem; the
  sampled reference selection or the least-bad velocity was used instead.
"""
from __future__ import annotations

import math
import numbers
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .formulations import cone_qp, nlp, plane_qp, sampled
from .formulations.common import Encounter, Options, Outcome, prepare
from .formulations.problem import NLP, QP, Result
from .solvers import FEAS_TOL, Backend, available_qp_solvers, available_solvers, get_backend, standardise
from .types import AgentState, Box, Cylinder, Limits, Neighbor, check_vector

FORMULATIONS = ("sampled", "plane_qp", "cone_qp", "nlp")
#: Default QP backend: the fastest on our benchmark (benchmarks/bench_select.py).
DEFAULT_QP_SOLVER = "daqp"
DEFAULT_NLP_SOLVER = "casadi"


@dataclass
class Decision:
    """What ``select`` returns. ``velocity`` (3,) m/s world frame; ``solve_time`` s."""

    velocity: np.ndarray
    status: str
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
    expected = " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
    for i, item in enumerate(items):
        if not isinstance(item, cls):
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
            return Result(None, "failed", backend.name, f"{type(exc).__name__}: {exc}")
        if not isinstance(res, Result):
            return Result(None, "failed", backend.name, "backend returned no Result")
        if res.status == "optimal" and not backend.checks_answers:
            qp = problem.qp if isinstance(problem, NLP) else problem
            x = None if res.x is None else np.asarray(res.x, dtype=float).reshape(-1)
            if x is None or x.shape != (qp.n,) or not np.all(np.isfinite(x)) or standardise(qp).violation(x) > FEAS_TOL:
                return Result(None, "failed", res.solver, "garbage answer rejected")
            return Result(x, "optimal", res.solver, res.info)
        return res

    return call


class VelocitySelector:
    """Chooses a safe velocity for one UAV per control period.

    ``formulation``: "sampled" (the paper's reference), "plane_qp" (default), "cone_qp", "nlp".
    ``solver``: a name from ``vo3d_opt.solvers.available_solvers()``; QP formulations default to
    the fastest QP backend, "nlp" to "casadi" (its start comes from plane_qp on ``start_solver``).
    Keyword options (see ``Options``): plane_step_deg, heading_step_deg, speed_levels,
    polygon_sides, reciprocal, horizon, corrections, n_samples, qp_samples, pz_buffer (m: plan
    with every neighbour's sphere this much larger), margin, and for nlp start_solver.
    """

    def __init__(self, formulation: str = "plane_qp", solver: str | None = None, *,
                 start_solver: str | None = None, **options) -> None:
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation: unknown {formulation!r}; available: {', '.join(FORMULATIONS)}")
        self.options = Options(**options)  # ValueError naming a wrong or unknown option
        self.formulation = formulation
        self._qp = self._nlp = None
        if formulation == "nlp":
            self.solver = solver or DEFAULT_NLP_SOLVER
            backend = get_backend(self.solver)
            if backend.kind != "nlp":
                raise ValueError(f"solver: formulation 'nlp' needs an NLP solver "
                                 f"({', '.join(s for s in available_solvers() if s.startswith('casadi'))}), got {solver!r}")
            self._nlp = backend
            self._qp = self._qp_backend(start_solver or DEFAULT_QP_SOLVER)
        elif formulation == "sampled":
            self.solver = None
            if solver is not None:
                get_backend(solver)  # a wrong name is still an error; sampled needs no solver
        else:
            self.solver = solver or DEFAULT_QP_SOLVER
            self._qp = self._qp_backend(self.solver)

    @staticmethod
    def _qp_backend(name: str):
        backend = get_backend(name)
        if backend.kind != "qp":
            raise ValueError(f"solver: {name!r} does not solve QPs; available: {', '.join(available_qp_solvers())}")
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
        neighbors = _items(neighbors, Neighbor, "neighbors")
        obstacles = _items(obstacles, (Cylinder, Box), "obstacles")
        limits = Limits() if limits is None else limits
        if not isinstance(limits, Limits):
            raise ValueError(f"limits: expected Limits, got {type(limits).__name__}")
        if isinstance(dt, bool) or not (isinstance(dt, numbers.Real) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt: must be a positive finite number of seconds, got {dt!r}")
        enc = prepare(own, v_pref, neighbors, obstacles, limits, float(dt), self.options)
        out = self._run(enc)
        v = _enforce_limits(enc, out.velocity)
        status = out.status
        if status == "optimal" and enc.inside_any:
            status = "inside_protected_zone"
        return Decision(velocity=v, status=status, solve_time=time.perf_counter() - t0,
                        formulation=self.formulation, solver=self.solver, plane=out.plane, info=out.info)

    def _run(self, enc: Encounter) -> Outcome:
        if self.formulation == "sampled":
            return sampled.select(enc)
        # The preferred velocity itself, when safe, is every formulation's optimum.
        if not enc.inside_any and enc.within_limits(enc.v_pref)[0] and not enc.pref_in.any():
            return Outcome(enc.v_pref.copy(), "optimal", None, {"round": "preferred"})
        solve = _checked(self._qp, "solve")
        if self.formulation == "plane_qp":
            return plane_qp.select(enc, solve, self._qp.has_cones)
        if self.formulation == "cone_qp":
            return cone_qp.select(enc, solve, self._qp.has_cones)
        return nlp.select(enc, solve, self._qp.has_cones, _checked(self._nlp, "solve_nlp"))


def _enforce_limits(enc: Encounter, v: np.ndarray) -> np.ndarray:
    """Last line of the contract: never above v_max, never leaving [z_min, z_max] within dt."""
    x, y, z = (c if math.isfinite(c) else 0.0 for c in np.asarray(v, dtype=float).tolist())
    lo, hi = enc.vz_range()
    z = min(max(z, lo), hi)
    speed = math.sqrt(x * x + y * y + z * z)
    if speed > enc.limits.v_max:
        x, y, z = (c * (enc.limits.v_max / speed) for c in (x, y, z))
    return np.array([x, y, z])
