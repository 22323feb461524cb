"""The problems the backends answer, and their answer.

A formulation builds one of these from the geometry; a backend turns it into a :class:`Result`.
Problems are tiny (2 or 3 variables, tens of constraints), so matrices are dense.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vo3d_opt.status import Status


@dataclass
class QP:
    """minimise ½ xᵀP x + qᵀx  subject to  G x <= h,  A x = b,  lb <= x <= ub,
    and, when ``soc_radius`` is set, the second-order cone ||x|| <= soc_radius (the speed bound).

    Backends without cones never see ``soc_radius``: the formulation replaces it with an
    inscribed polygon first (see ``has_cones`` on each backend).
    """

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray | None = None
    h: np.ndarray | None = None
    A: np.ndarray | None = None
    b: np.ndarray | None = None
    lb: np.ndarray | None = None
    ub: np.ndarray | None = None
    soc_radius: float | None = None

    @property
    def n(self) -> int:
        return int(self.q.shape[0])


@dataclass
class ConeConstraint:
    """Exact 'outside the VO cone' constraint for the NLP: the angle between v - apex and the
    unit axis is at least alpha, written smoothly as
    axis·(v - apex) - cos_alpha * sqrt(|v - apex|² + eps²) <= 0."""

    apex: np.ndarray
    axis: np.ndarray
    cos_alpha: float


@dataclass
class NLP:
    """The QP's objective and linear constraints plus exact (non-convex) cone constraints,
    started from ``x0``."""

    qp: QP
    cones: list[ConeConstraint] = field(default_factory=list)
    x0: np.ndarray | None = None


@dataclass
class Result:
    """A backend's answer: ``status`` is Status.OPTIMAL, INFEASIBLE or FAILED."""

    x: np.ndarray | None
    status: Status
    solver: str
    info: str = ""

    @property
    def ok(self) -> bool:
        return (
            self.status == Status.OPTIMAL
            and self.x is not None
            and bool(np.all(np.isfinite(self.x)))
        )
