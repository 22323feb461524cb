"""plane_qp's internals: the closed-form lower bounds that order and prune its QPs must never
exceed a QP's true optimum, and may call a QP infeasible only when it is."""
from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from encounters import encounters
from vo3d_opt.formulations import plane_qp
from vo3d_opt.formulations.common import Options, prepare
from vo3d_opt.solvers import get_backend

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


@settings(max_examples=30, **SETTINGS)
@given(kw=encounters(), seed=st.integers(0, 2**31), cones=st.booleans())
def test_bounds_are_lower_bounds_and_prove_only_true_infeasibility(kw, seed, cones):
    enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"], float), kw["neighbors"],
                  kw["obstacles"], kw["limits"], kw["dt"], Options(reciprocal=bool(seed % 2)))
    problems = plane_qp.PlaneProblems(enc, plane_qp.decision_planes(enc), has_cones=cones)
    problems.ensure(np.ones(len(problems.computed), dtype=bool))  # every VO's rows
    reference = get_backend("clarabel")
    rng = np.random.default_rng(seed)
    P = len(problems.planes.phi)
    checked = infeasible = 0
    for r in range(len(plane_qp.ROUNDS)):
        included = rng.random(len(problems.computed)) < 0.6
        lb = problems.bounds(included, np.full(P, r), np.arange(P))
        for p in range(P):
            assert lb[p] == problems.bound(r, p, included)
            qp = problems.qp(r, p, included)
            res = reference.solve(qp)
            if res.status == "optimal":
                checked += 1
                assert lb[p] <= np.linalg.norm(res.x - problems.w0) + 1e-7
            if not np.isfinite(lb[p]):
                infeasible += 1
                assert res.status == "infeasible"
    assert checked + infeasible > 0
