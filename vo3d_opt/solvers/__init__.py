"""Solver backends: one small module per solver behind one interface, chosen by a string.

``get_backend("osqp")`` returns a :class:`Backend` whose ``solve(qp)`` answers a :class:`QP`
(or whose ``solve_nlp(nlp)`` answers an :class:`NLP`) with a :class:`Result`. The interface
and the shared checks are in ``base.py``, the names in ``registry.py``, one module per solver
beside them; ``exact2d.py`` is this package's own exact solver of the per-plane problem.
Every backend answers "optimal" only when its x is finite and satisfies every constraint within
:data:`FEAS_TOL`, "infeasible" when infeasibility is proved, "failed" otherwise, and never
raises on a well-formed problem.
"""

from vo3d_opt.solvers.base import (
    FEAS_TOL,
    Backend,
    Standard,
    failure,
    make_result,
    require_no_cone,
    screen,
    standardise,
)
from vo3d_opt.solvers.certify import certified_infeasible
from vo3d_opt.solvers.problem import NLP, QP, ConeConstraint, Result
from vo3d_opt.solvers.registry import (
    CASADI_PLUGINS,
    available_qp_solvers,
    available_solvers,
    get_backend,
    register_backend,
    unregister_backend,
)

__all__ = [
    "Backend",
    "CASADI_PLUGINS",
    "ConeConstraint",
    "FEAS_TOL",
    "NLP",
    "QP",
    "Result",
    "Standard",
    "available_qp_solvers",
    "available_solvers",
    "certified_infeasible",
    "failure",
    "get_backend",
    "make_result",
    "register_backend",
    "require_no_cone",
    "screen",
    "standardise",
    "unregister_backend",
]
