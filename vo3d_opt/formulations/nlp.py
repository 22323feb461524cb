"""nlp — the exact, non-convex VO constraints (formulations/nlp.md).

Started from the best QP answer (plane_qp on a QP backend), it keeps the exact cone constraints
angle(v - apex, axis) >= alpha (curved, not linearised), the pyramid face the start is outside of,
and the same limits, and minimises ||v - v_pref||². The answer replaces the start only when it
passes the exact 3D check, respects the limits and is strictly nearer the preferred velocity:
the NLP never returns anything worse than its start."""
from __future__ import annotations

import numpy as np

from .common import Encounter, Outcome, Solve, SolveNLP, first_safe
from .cone_qp import pyramid_face_halfspaces
from . import plane_qp
from .problem import NLP, QP, ConeConstraint


#: Metres added to every protected radius in the exact cone constraints.
RADIUS_MARGIN = 1e-3


def build_nlp(enc: Encounter, start: np.ndarray) -> NLP:
    c = enc.cones
    # The protected sphere grows by a hair (m) so that IPOPT's answer on the boundary, within
    # its tolerance, is still strictly outside the exact VO.
    sin_a = np.minimum((c.r_pz + RADIUS_MARGIN) / np.maximum(c.d_oi, 1e-12), 1.0)
    cos_a = np.sqrt(1.0 - sin_a**2)
    cones = [ConeConstraint(apex=c.apex[i], axis=c.axis[i], cos_alpha=float(cos_a[i]))
             for i in range(len(c)) if not c.inside[i]]
    rows_G, rows_h = [], []
    if np.any(c.inside):  # escape half-spaces stay linear
        rows_G.append(c.rel[c.inside])
        rows_h.append(np.sum(c.rel * c.apex, axis=1)[c.inside])
    if len(enc.pyramids):
        N, b = pyramid_face_halfspaces(enc.pyramids, start)
        rows_G.append(-N)
        rows_h.append(-b - enc.options.margin)
    G3, h3 = enc.linear_bounds()
    rows_G.append(G3)
    rows_h.append(h3)
    qp = QP(P=2.0 * np.eye(3), q=-2.0 * enc.v_pref, G=np.vstack(rows_G), h=np.concatenate(rows_h),
            soc_radius=enc.limits.v_max)
    return NLP(qp=qp, cones=cones, x0=start)


def select(enc: Encounter, solve_qp: Solve, qp_has_cones: bool, solve_nlp: SolveNLP) -> Outcome:
    start = plane_qp.select(enc, solve_qp, qp_has_cones)
    if start.status != "optimal":
        return start
    res = solve_nlp(build_nlp(enc, start.velocity))
    if res.ok and res.x.shape == (3,):
        better = enc.deviation(res.x)[0] < enc.deviation(start.velocity)[0] - 1e-9
        if better and first_safe(enc, res.x[None]) is not None:
            return Outcome(res.x, "optimal", None, {"round": "nlp", "start": start.velocity})
    info = dict(start.info, nlp=res.status)
    return Outcome(start.velocity, "optimal", start.plane, info)
