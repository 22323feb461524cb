"""CasADi ``nlpsol`` (ipopt by default) for the NLP with exact, non-convex VO cone constraints.

Variables x (n); objective ½xᵀPx + qᵀx; constraints: the linear rows ``[G; A] x`` (G rows
bounded above by h, A rows fixed to b), ``x·x <= r²`` (no upper bound without ``soc_radius``)
and, for each cone, ``axis·(x - apex) - cos_alpha·sqrt(|x - apex|² + 1e-9) <= 0``; ``lb``/``ub``
are the variable bounds. The symbolic problem and its solver are built once per (n, linear rows,
cones) with all data as parameters.

"optimal" needs both the plugin's success flag and a returned x satisfying every constraint
within 1e-6. When the start x0 is feasible and the solver ends somewhere worse (or fails), the
start is returned instead, with status "failed": never a worse answer than the caller had.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from vo3d_opt.solvers.base import Backend, Standard, failure, make_result, screen, standardise
from vo3d_opt.solvers.problem import NLP, QP, ConeConstraint, Result
from vo3d_opt.status import Status

#: Smoothing of the cone constraint's norm (inside the square root).
CONE_EPS = 1e-9
#: Largest violation of any constraint (absolute) at an "optimal" x.
NLP_TOL = 1e-6

#: Quiet options per plugin.
PLUGIN_OPTIONS: dict[str, dict[str, object]] = {
    "ipopt": {
        "ipopt.print_level": 0,
        "print_time": False,
        "ipopt.sb": "yes",
        "ipopt.tol": 1e-9,
        "ipopt.max_iter": 500,
    },
    "sqpmethod": {
        "print_header": False,
        "print_iteration": False,
        "print_time": False,
        "print_status": False,
        "qpsol": "qrqp",
        "max_iter": 200,
        "convexify_strategy": "regularize",
        "qpsol_options": {
            "print_iter": False,
            "print_header": False,
            "print_info": False,
            "error_on_fail": False,
        },
    },
}

_INFEASIBLE = {"Infeasible_Problem_Detected"}


def cone_values(cones: list[ConeConstraint], x: np.ndarray) -> np.ndarray:
    """The smooth cone constraint functions at x (each must be <= 0)."""
    if not cones:
        return np.empty(0)
    apex = np.array([c.apex for c in cones], dtype=float)
    axis = np.array([c.axis for c in cones], dtype=float)
    cos = np.array([c.cos_alpha for c in cones], dtype=float)
    d = x - apex
    return np.einsum("ij,ij->i", axis, d) - cos * np.sqrt(np.einsum("ij,ij->i", d, d) + CONE_EPS)


def nlp_violation(std: Standard, cones: list[ConeConstraint], x: np.ndarray) -> float:
    """Largest absolute constraint violation of x (0 when feasible)."""
    Cx = std.C @ x
    worst = max(0.0, (std.l - Cx).max(), (Cx - std.u).max(), cone_values(cones, x).max(initial=0.0))
    if std.r is not None:
        worst = max(worst, float(np.sqrt(x @ x)) - std.r)
    return float(worst)


def objective(std: Standard, x: np.ndarray) -> float:
    """½xᵀPx + qᵀx."""
    return float(0.5 * x @ std.P @ x + std.q @ x)


def _build(plugin: str, n: int, m: int, k: int) -> ca.Function:
    """The nlpsol for n variables, m linear rows and k cones; parameters as in :func:`_params`."""
    x = ca.SX.sym("x", n)
    P, q, C = ca.SX.sym("P", n, n), ca.SX.sym("q", n), ca.SX.sym("C", m, n)
    apex, axis, cos = ca.SX.sym("apex", n, k), ca.SX.sym("axis", n, k), ca.SX.sym("cos", k)
    g = [C @ x, ca.dot(x, x)]
    for i in range(k):
        d = x - apex[:, i]
        g.append(ca.dot(axis[:, i], d) - cos[i] * ca.sqrt(ca.dot(d, d) + CONE_EPS))
    problem = {
        "x": x,
        "f": 0.5 * ca.dot(x, P @ x) + ca.dot(q, x),
        "g": ca.vertcat(*g),
        "p": ca.vertcat(ca.vec(P), q, ca.vec(C), ca.vec(apex), ca.vec(axis), cos),
    }
    options: dict[str, Any] = {**PLUGIN_OPTIONS[plugin], "error_on_fail": False}
    return ca.nlpsol(f"vo3d_{plugin}_{n}_{m}_{k}", plugin, problem, options)


def _params(std: Standard, cones: list[ConeConstraint]) -> np.ndarray:
    """The parameter vector of :func:`_build` (column-major, as ``ca.vec``)."""
    m, k = std.m_ineq + std.m_eq, len(cones)
    apex = np.array([c.apex for c in cones], dtype=float).reshape(k, std.n)
    axis = np.array([c.axis for c in cones], dtype=float).reshape(k, std.n)
    cos = np.array([c.cos_alpha for c in cones], dtype=float)
    return np.concatenate(
        [std.P.ravel(order="F"), std.q, std.C[:m].ravel(order="F"), apex.ravel(), axis.ravel(), cos]
    )


class CasadiBackend(Backend):
    """A CasADi nlpsol plugin on the exact NLP; ``solve(qp)`` treats a QP as a cone-free NLP."""

    has_cones = True
    kind = "nlp"
    checks_answers = True

    def __init__(self, name: str, plugin: str) -> None:
        self.name = name
        self._plugin = plugin
        self._solvers: dict[tuple[int, int, int], ca.Function] = {}

    def solve(self, qp: QP) -> Result:
        """Solve ``qp`` as an NLP without cones, started from zero."""
        return self.solve_nlp(NLP(qp=qp))

    def solve_nlp(self, nlp: NLP) -> Result:
        """Solve ``nlp`` from ``nlp.x0`` (zeros when None)."""
        std = standardise(nlp.qp)
        n, cones = std.n, list(nlp.cones)
        for c in cones:
            if np.shape(c.apex) != (n,) or np.shape(c.axis) != (n,):
                raise ValueError(f"ConeConstraint apex and axis must have shape ({n},)")
        x0 = np.zeros(n) if nlp.x0 is None else np.asarray(nlp.x0, dtype=float).reshape(-1)
        if x0.shape != (n,):
            raise ValueError(f"NLP.x0 must have shape ({n},), got {np.asarray(nlp.x0).shape}")
        if (early := screen(std, self.name)) is not None:
            return early
        cone_data = np.array([[*c.apex, *c.axis, c.cos_alpha] for c in cones], dtype=float)
        if not (np.isfinite(cone_data).all() and np.isfinite(x0).all()):
            return Result(None, Status.FAILED, self.name, "cone data or x0 is not finite")
        try:
            result = self._run(std, cones, x0)
        except Exception as exc:  # noqa: BLE001 - a backend never raises on a well-formed NLP
            result = failure(self.name, exc)
        return self._no_worse_than_start(std, cones, x0, result)

    def _run(self, std: Standard, cones: list[ConeConstraint], x0: np.ndarray) -> Result:
        m, k = std.m_ineq + std.m_eq, len(cones)
        key = (std.n, m, k)
        if key not in self._solvers:
            self._solvers[key] = _build(self._plugin, *key)
        solver = self._solvers[key]
        sol = solver(
            x0=x0,
            p=_params(std, cones),
            lbx=std.l[m:],
            ubx=std.u[m:],
            lbg=np.concatenate([std.l[:m], np.full(1 + k, -np.inf)]),
            ubg=np.concatenate([std.u[:m], [np.inf if std.r is None else std.r**2], np.zeros(k)]),
        )
        stats = solver.stats()
        native = str(stats.get("return_status", ""))
        x = np.array(sol["x"], dtype=float).reshape(-1)
        if native in _INFEASIBLE:
            return Result(None, Status.INFEASIBLE, self.name, native)
        if not stats.get("success", False):
            return make_result(self.name, std, x, Status.FAILED, native)
        if not np.isfinite(x).all() or nlp_violation(std, cones, x) > NLP_TOL:
            return make_result(
                self.name, std, x, Status.FAILED, f"{native}, but x violates constraints"
            )
        return Result(x, Status.OPTIMAL, self.name, native)

    def _no_worse_than_start(
        self, std: Standard, cones: list[ConeConstraint], x0: np.ndarray, result: Result
    ) -> Result:
        """``result``, or the feasible start x0 when the solver ended worse than it."""
        if nlp_violation(std, cones, x0) > NLP_TOL:
            return result
        if (
            result.ok
            and result.x is not None
            and objective(std, result.x) <= objective(std, x0) + 1e-9
        ):
            return result
        return Result(
            x0.copy(),
            Status.FAILED,
            self.name,
            f"{result.status} ({result.info}); returning the feasible start x0",
        )
