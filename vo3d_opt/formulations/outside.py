"""The Python path: the formulations that do not run as one compiled call.

``sampled`` (the paper's reference), and ``plane_qp``, ``cone_qp`` and ``nlp`` on outside
backends: each builds its problems from the same compiled geometry (``Encounter``) and hands
them to a backend of ``vo3d_opt.solvers`` through ``checked``, so that a misbehaving backend can
never crash the control loop. ``nlp`` on exact2d starts from the compiled decision.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..extras import MissingExtra
from ..solvers import (
    FEAS_TOL,
    NLP,
    QP,
    Backend,
    Result,
    available_qp_solvers,
    get_backend,
    standardise,
)
from ..status import DECISION_STATUSES, Status
from . import kernel
from .common import Encounter, Outcome, Solve, bounds_array
from .cone_qp import select_cone_qp
from .nlp import select_nlp
from .plane_qp import select_plane_qp
from .sampled import select_sampled


def checked(backend: Backend, method: str) -> Callable[[QP | NLP], Result]:
    """A backend call whose exceptions, and answers from outside backends that break the
    problem's own constraints, become "failed" results."""
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


def backend_for(name: str, formulation: str) -> Backend:
    """``get_backend(name)``; a solver library not installed is said with the formulation."""
    try:
        return get_backend(name)
    except MissingExtra as exc:
        raise exc.within(f"formulation {formulation!r}") from None


def qp_backend(name: str, formulation: str) -> Backend:
    """The QP backend ``name`` for ``formulation``; ValueError when it cannot serve."""
    backend = backend_for(name, formulation)
    if backend.kind != "qp":
        raise ValueError(
            f"solver: {name!r} does not solve QPs; available: {', '.join(available_qp_solvers())}"
        )
    if backend.name == "exact2d" and formulation != "plane_qp":
        raise ValueError(
            f"solver: 'exact2d' solves plane_qp's 2-variable problems only, "
            f"not {formulation}'s; "
            f"available: {', '.join(s for s in available_qp_solvers() if s != 'exact2d')}"
        )
    return backend


@dataclass(frozen=True)
class PythonPath:
    """A formulation on the Python path and its backends (``qp``: every formulation but
    sampled; ``nlp``: formulation "nlp", started from plane_qp on ``qp``)."""

    formulation: str
    qp: Backend | None = None
    nlp: Backend | None = None

    def run(self, enc: Encounter, prisms: np.ndarray) -> Outcome:
        """The formulation's answer to ``enc`` (``prisms``: its obstacles' rows)."""
        if self.formulation == "sampled":
            return select_sampled(enc)
        # The preferred velocity itself, when safe, is every formulation's optimum.
        if not enc.inside_any and enc.within_limits(enc.v_pref)[0] and not enc.pref_in.any():
            return Outcome(enc.v_pref.copy(), Status.OPTIMAL, None, {"round": "preferred"})
        assert self.qp is not None  # every formulation but sampled has a QP backend
        solve = checked(self.qp, "solve")
        if self.formulation == "cone_qp":
            return select_cone_qp(enc, solve, self.qp.has_cones)
        start = self._plane_qp(enc, prisms, solve)
        if self.formulation == "plane_qp":
            return start
        assert self.nlp is not None  # set for formulation "nlp"
        return select_nlp(enc, start, checked(self.nlp, "solve_nlp"))

    def _plane_qp(self, enc: Encounter, prisms: np.ndarray, solve: Solve) -> Outcome:
        assert self.qp is not None
        if self.qp.name != "exact2d":
            return select_plane_qp(enc, solve, self.qp.has_cones)
        out = np.empty(kernel.OUT_SIZE)
        kernel.decide(
            enc.position,
            enc.v_now,
            enc.v_pref,
            enc.nbrs,
            prisms,
            bounds_array(enc.limits, enc.dt),
            enc.options.config,
            out,
        )
        _, _, _, status, phi, rnd, solved = out.tolist()
        answer = DECISION_STATUSES[int(status)]
        return Outcome(
            out[:3],
            Status.OPTIMAL if answer == Status.INSIDE_PROTECTED_ZONE else answer,
            None if math.isnan(phi) else phi,
            {"round": kernel.ROUND_NAMES[int(rnd)], "solved": int(solved)},
        )
