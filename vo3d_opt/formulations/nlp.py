"""nlp — the exact, non-convex VO constraints (formulations/nlp.md).

Started from the best QP answer (plane_qp on a QP backend), it keeps the exact cone constraints
angle(v - apex, axis) >= alpha (curved, not linearised), the pyramid face the start is outside of,
and the same limits, and minimises ||v - v_pref||². The answer replaces the start only when it
passes the exact 3D check, respects the limits and is strictly nearer the preferred velocity:
the NLP never returns anything worse than its start."""

from __future__ import annotations

import numpy as np

from ..geometry.pyramid import supporting_faces
from ..solvers import NLP, QP, ConeConstraint
from ..status import Status
from .common import Encounter, Outcome, SolveNLP
from .fallback import first_safe

#: Metres added to every protected radius in the exact cone constraints.
RADIUS_MARGIN = 1e-3


def build_nlp(enc: Encounter, start: np.ndarray) -> NLP:
    c = enc.cones
    # The protected sphere grows by a hair (m) so that IPOPT's answer on the boundary, within
    # its tolerance, is still strictly outside the exact VO.
    sin_a = np.minimum((c.r_pz + RADIUS_MARGIN) / np.maximum(c.d_oi, 1e-12), 1.0)
    cos_a = np.sqrt(1.0 - sin_a**2)
    cones = [
        ConeConstraint(apex=c.apex[i], axis=c.axis[i], cos_alpha=float(cos_a[i]))
        for i in range(c.n)
        if not c.inside[i]
    ]
    rows_G, rows_h = [], []
    if np.any(c.inside):  # escape half-spaces stay linear
        rows_G.append(c.rel[c.inside])
        rows_h.append(np.sum(c.rel * c.apex, axis=1)[c.inside])
    if enc.pyramids.n:
        N, b = supporting_faces(enc.pyramids, start)
        rows_G.append(-N)
        rows_h.append(-b - enc.options.margin)
    G3, h3 = enc.qp_bounds()
    rows_G.append(G3)
    rows_h.append(h3)
    qp = QP(
        P=2.0 * np.eye(3),
        q=-2.0 * enc.v_pref,
        G=np.vstack(rows_G),
        h=np.concatenate(rows_h),
        soc_radius=enc.limits.v_max,
    )
    return NLP(qp=qp, cones=cones, x0=start)


def select_nlp(enc: Encounter, start: Outcome, solve_nlp: SolveNLP) -> Outcome:
    """Improve ``start`` (plane_qp's decision) with the exact constraints, never worsening it."""
    if start.status != Status.OPTIMAL:
        return start
    res = solve_nlp(build_nlp(enc, start.velocity))
    if res.ok and res.x is not None and res.x.shape == (3,):
        better = enc.deviation(res.x)[0] < enc.deviation(start.velocity)[0] - 1e-9
        if better and first_safe(enc, res.x[None]) is not None:
            return Outcome(res.x, Status.OPTIMAL, None, {"round": "nlp", "start": start.velocity})
    info = dict(start.info, nlp=res.status)
    return Outcome(start.velocity, Status.OPTIMAL, start.plane, info)
