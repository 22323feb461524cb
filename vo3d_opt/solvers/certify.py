"""A second opinion on infeasibility, for backends whose solver reports only "no solution"
(qpsolvers) or calls feasible problems infeasible (ProxQP)."""

from __future__ import annotations

import functools
import importlib.util

from vo3d_opt.solvers.base import Backend
from vo3d_opt.solvers.problem import QP
from vo3d_opt.status import Status


@functools.cache
def _clarabel() -> Backend | None:
    if importlib.util.find_spec("clarabel") is None:
        return None
    from vo3d_opt.solvers.clarabel_backend import ClarabelBackend

    return ClarabelBackend()


def certified_infeasible(qp: QP) -> bool:
    """Whether Clarabel proves ``qp`` infeasible (False when Clarabel is not installed). Costs
    one Clarabel solve (tens of microseconds), on failures only."""
    backend = _clarabel()
    return backend is not None and backend.solve(qp).status == Status.INFEASIBLE
