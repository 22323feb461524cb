"""plane_qp's internals: the closed-form lower bounds that order and prune its QPs must never
exceed a QP's true optimum, and may call a QP infeasible only when it is."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from encounters import encounters
from vo3d_opt import AgentState, Cylinder, Limits, Neighbor
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


def _exhaustive(enc, solve, has_cones):
    """plane_qp without bounds or ordering: every (round, plane) QP taken to its own fixpoint of
    constraint generation; the least deviation among the safe answers within the limits."""
    problems = plane_qp.PlaneProblems(enc, plane_qp.decision_planes(enc), has_cones)
    best = np.inf
    for r in range(len(plane_qp.ROUNDS)):
        for p in range(len(problems.planes.phi)):
            included = problems.initial.copy()
            while True:
                res = solve(problems.qp(r, p, included))
                if res.status != "optimal":
                    break
                v = res.x[0] * problems.planes.e1 + res.x[1] * problems.planes.e2[p]
                entered = enc.containing(v)[:, 0]
                if not entered.any():
                    if enc.within_limits(v)[0]:
                        best = min(best, float(np.linalg.norm(v - enc.v_pref)))
                    break
                if np.all(included[entered]):
                    break
                problems.ensure(entered)
                included = included | entered
    return best


@settings(max_examples=60, **SETTINGS)
@given(kw=encounters(), cones=st.booleans())
def test_search_finds_what_exhaustive_search_finds(kw, cones):
    """The bounds only prune QPs that cannot do better, and a QP's answer does not depend on the
    order the QPs are solved in: the best-first search returns the exhaustive optimum."""
    v_pref = np.asarray(kw["preferred_velocity"], float)
    u = v_pref / np.linalg.norm(v_pref)
    head_on = Neighbor(position=kw["own"].position + 25.0 * u, velocity=-u, r_pz=6.0)  # a conflict
    enc = prepare(kw["own"], v_pref, [head_on, *kw["neighbors"]], kw["obstacles"], kw["limits"],
                  kw["dt"], Options())
    assert enc.unsafe(enc.v_pref)[0]
    backend = get_backend("clarabel" if cones else "daqp")
    expected = _exhaustive(enc, backend.solve, cones)
    out = plane_qp.select(enc, backend.solve, cones)
    if np.isfinite(expected):
        assert out.status == "optimal" and out.info["round"] != "sampled"
        assert np.linalg.norm(out.velocity - enc.v_pref) == pytest.approx(expected, abs=1e-6)


def test_an_answer_does_not_depend_on_other_planes():
    """A found case (review of the bounds): sharing the VOs one plane's answer entered with
    every plane made another plane's QP infeasible and the answer 1 m/s worse than the
    exhaustive search's."""
    own = AgentState(position=[0, 0, 50], velocity=[-5.3796, -0.6570, 2.9143])
    v_pref = np.array([0.77143, -1.60623, -12.04291])
    nbs = [Neighbor(position=p, velocity=v, r_pz=r) for p, v, r in [
        ([3.09398, 11.00943, 54.13071], [-6.48237, -1.81634, -7.19370], 7.87338),
        ([11.26795, -3.81608, 54.05331], [-2.24078, -7.38452, -2.42938], 6.77138),
        ([-4.87394, 1.36212, 55.47700], [6.26668, -1.88030, 0.96140], 3.28714),
        ([4.09004, -23.17019, 43.40760], [3.74853, -5.83477, 0.99736], 3.79547),
        ([-15.56925, -1.92732, 51.48983], [-0.20407, -7.91324, 1.46749], 6.42688)]]
    obs = [Cylinder(center=[2.99423, -4.85748], radius=3.58231, height=78.50985),
           Cylinder(center=[-6.09207, -13.14127], radius=1.62802, height=37.96168)]
    limits = Limits(speed=(0.0, 10.0), altitude=(52.42431, 100.0), acceleration=5.0)
    enc = prepare(own, v_pref, nbs, obs, limits, 0.5, Options(margin=0.5))
    for name, cones in (("clarabel", True), ("daqp", False)):
        backend = get_backend(name)
        out = plane_qp.select(enc, backend.solve, cones)
        expected = _exhaustive(enc, backend.solve, cones)
        assert np.linalg.norm(out.velocity - enc.v_pref) == pytest.approx(expected, abs=1e-6)
