"""The statuses every layer reports: a solver's answer, a decision, a simulated step.

``Status`` is a ``str`` (a ``StrEnum``), so ``decision.status == "optimal"`` holds and JSON
writes the plain name (``decision.status`` is a str).
"""

from __future__ import annotations

from enum import StrEnum


class Status(StrEnum):
    """What happened. A solver's ``Result`` is OPTIMAL, INFEASIBLE or FAILED; a ``Decision``
    is OPTIMAL or one of the last three, which say why the velocity is not a plain optimum."""

    #: Solver: the optimum of the problem. Decision: a velocity outside every VO (exact 3D
    #: check) and within the limits, the nearest to the preferred velocity found.
    OPTIMAL = "optimal"
    #: Solver: the problem has no feasible point (proved).
    INFEASIBLE = "infeasible"
    #: Solver: no answer (an error, a limit, an answer that breaks the constraints).
    FAILED = "failed"
    #: Decision: the vehicle is already inside a protected zone; the velocity is the best escape
    #: found (not closing on any zone it is inside, outside the other VOs when possible).
    INSIDE_PROTECTED_ZONE = "inside_protected_zone"
    #: Decision: no velocity within the limits is outside every VO; the one whose first
    #: protected-zone intrusion comes latest is returned (ties at once, inside zones: the one
    #: closing slowest on them, ``least_bad_escape``, the default; then nearest the preferred
    #: velocity).
    INFEASIBLE_MIN_VIOLATION = "infeasible_min_violation"
    #: Decision: the backend failed on every problem; the fallbacks' grid's safe velocity or the
    #: least-bad one was used instead.
    SOLVER_FAILED_FALLBACK = "solver_failed_fallback"


#: The statuses a decision can have, in the order of their integer codes in compiled code.
DECISION_STATUSES = (
    Status.OPTIMAL,
    Status.INSIDE_PROTECTED_ZONE,
    Status.INFEASIBLE_MIN_VIOLATION,
    Status.SOLVER_FAILED_FALLBACK,
)
