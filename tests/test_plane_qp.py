"""plane_qp's search: best first over the (round, plane) QPs with constraint generation per QP
must return what taking every QP to its own fixpoint returns, on the compiled default path
(exact2d) and on outside backends (whose QPs the exact optima bound from below)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from encounters import encounters
from vo3d_opt import AgentState, Cylinder, Limits, Neighbor, VelocitySelector
from vo3d_opt.formulations import plane_qp
from vo3d_opt.formulations.common import (
    Bounds,
    Options,
    neighbor_rows,
    prepare,
    py_decision_planes,
    py_pref_clear,
)
from vo3d_opt.formulations.kernel import py_lift, py_plane_qps, py_search
from vo3d_opt.formulations.rows import ROUNDS, py_pick
from vo3d_opt.geometry.pyramid import prism_rows
from vo3d_opt.solvers import QP, get_backend
from vo3d_opt.status import Status

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


def _exhaustive(enc, solve, has_cones):
    """plane_qp without ordering or bounds: every (round, plane) QP taken to its own fixpoint of
    constraint generation; the least deviation among the safe answers within the limits."""
    cfg = enc.options.config
    planes = py_decision_planes(enc.vos, enc.v_now, cfg)
    G3, h3 = enc.qp_bounds()
    qps = py_plane_qps(enc.vos, planes, G3, h3, enc.pref_in | enc.inside, cfg, False)
    G_speed, h_speed = (np.zeros((0, 2)), np.zeros(0)) if has_cones else plane_qp.speed_polygon(
        enc.limits.v_max, enc.options.polygon_sides)
    best, v = np.inf, np.empty(3)
    for r in range(len(ROUNDS)):
        for p in range(len(planes.phi)):
            while True:
                m = qps.gather(r, p)
                res = solve(QP(P=2 * np.eye(2), q=-2 * qps.w0, G=np.vstack([qps.rows[:m], G_speed]),
                               h=np.concatenate([qps.rhs[:m], h_speed]),
                               soc_radius=enc.limits.v_max if has_cones else None))
                if res.status != Status.OPTIMAL:
                    break
                py_lift(planes, np.ascontiguousarray(res.x), p, v)
                entered = enc.containing(v)[:, 0]
                if not entered.any():
                    if enc.within_limits(v)[0]:
                        best = min(best, float(np.linalg.norm(v - enc.v_pref)))
                    break
                if np.all(qps.included[r, p][entered]):
                    break
                for k in np.flatnonzero(entered):
                    qps.add_rows(int(k), p)
                qps.included[r, p] |= entered
    return best


def _conflict(kw):
    """The encounter with a head-on neighbour added, so that every call has to avoid."""
    v_pref = np.asarray(kw["preferred_velocity"], float)
    u = v_pref / np.linalg.norm(v_pref)
    head_on = Neighbor(position=kw["own"].position + 25.0 * u, velocity=-u, r_pz=6.0)
    return dict(kw, neighbors=[head_on, *kw["neighbors"]])


@settings(max_examples=60, **SETTINGS)
@given(kw=encounters(), solver=st.sampled_from(["exact2d", "clarabel", "daqp"]))
def test_search_finds_what_exhaustive_search_finds(kw, solver):
    """Best first, each QP's answer independent of the order: the search returns the
    exhaustive optimum on every backend (exact2d: the compiled kernel)."""
    kw = _conflict(kw)
    enc = prepare(kw["own"], kw["preferred_velocity"], kw["neighbors"], kw["obstacles"], kw["limits"],
                  kw["dt"], Options())
    assert enc.unsafe(enc.v_pref)[0]
    backend = get_backend(solver)
    expected = _exhaustive(enc, backend.solve, backend.has_cones)
    d = VelocitySelector(solver=solver, preset="paper").select(**kw)
    if np.isfinite(expected):
        assert d.status == Status.OPTIMAL and d.info["round"] in ROUNDS
        assert np.linalg.norm(d.velocity - enc.v_pref) == pytest.approx(expected, abs=1e-6)
    else:
        assert d.info["round"] in ("sampled", "least_bad")


def test_an_answer_does_not_depend_on_other_planes():
    """A found case: sharing the VOs one plane's answer entered with every plane made another
    plane's QP infeasible and the answer 1 m/s worse than the exhaustive search's."""
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
    kw = dict(own=own, preferred_velocity=v_pref, neighbors=nbs, obstacles=obs, limits=limits, dt=0.5)
    enc = prepare(own, v_pref, nbs, obs, limits, 0.5, Options(margin=0.5))
    for name in ("exact2d", "clarabel", "daqp"):
        backend = get_backend(name)
        d = VelocitySelector(solver=name, preset="paper", margin=0.5).select(**kw)
        expected = _exhaustive(enc, backend.solve, backend.has_cones)
        assert np.linalg.norm(d.velocity - enc.v_pref) == pytest.approx(expected, abs=1e-6)


@settings(max_examples=80, **SETTINGS)
@given(kw=encounters(max_neighbors=16))
def test_rows_on_demand_give_the_same_search_bit_for_bit(kw):
    """The kernel builds the rows of the VOs every QP starts with on plane 0 and elsewhere the
    probe's only, completing a plane when one of its QPs first comes up. A bound from fewer
    half-planes is still a lower bound, so the search must solve the same QPs in the same
    order as with every plane built: the same answer, QP count, tried answers, bit for bit."""
    kw = _conflict(kw)
    enc = prepare(kw["own"], kw["preferred_velocity"], kw["neighbors"], kw["obstacles"], kw["limits"],
                  kw["dt"], Options())
    cfg = enc.options.config
    planes = py_decision_planes(enc.vos, enc.v_now, cfg)
    G3, h3 = enc.linear_bounds()
    runs = []
    for lazy in (True, False):
        qps = py_plane_qps(enc.vos, planes, G3, h3, enc.pref_in | enc.inside, cfg, lazy)
        R, P = qps.key.shape
        tried = np.full((R * P * (qps.included.shape[2] + 1), 3), np.nan)
        out = py_search(qps, enc.bounds, tried)
        runs.append((out, tried, qps.sol))
    (a, tried_a, sol_a), (b, tried_b, sol_b) = runs
    assert a == b
    np.testing.assert_array_equal(tried_a[: a[3]], tried_b[: b[3]])
    if a[0] >= 0:
        np.testing.assert_array_equal(sol_a[a[0], a[1]], sol_b[b[0], b[1]])


def _pick_reference(curve: np.ndarray, chord: np.ndarray, w0: np.ndarray) -> tuple[int, int, int]:
    """The boundary candidates of the three rounds, written out: "near" the first of the least
    distance to w0, "left" / "right" the first of the least distance with y at or above /
    at or below the candidates' mean y (the nearest when none); NaN x: no candidate."""
    pts = np.concatenate([curve.T, chord])
    ok = ~np.isnan(pts[:, 0])
    dist = np.where(ok, ((pts - w0) ** 2).sum(axis=1), np.inf)
    total = 0.0
    for y in pts[ok, 1]:  # the kernel's order of summation
        total += y
    centre = total / max(int(ok.sum()), 1)

    def first_least(mask: np.ndarray) -> int:
        best, d_best = -1, np.inf
        for k in np.flatnonzero(mask):
            if dist[k] < d_best:
                best, d_best = k, dist[k]
        return best

    near = max(first_least(np.ones(len(pts), dtype=bool)), 0)
    left, right = first_least(pts[:, 1] >= centre), first_least(pts[:, 1] <= centre)
    return near, (near if left < 0 else left), (near if right < 0 else right)


@pytest.mark.parametrize("seed", range(40))
def test_the_rounds_boundary_points_are_the_nearest_of_each_half(seed: int) -> None:
    """``_pick`` (which searches only the half the nearest is not in) against the reference, on
    candidates with missing points, tied distances and points on the centre line."""
    rng = np.random.default_rng(seed)
    K = int(rng.integers(4, 40))
    for _ in range(50):
        # coarse coordinates: ties in distance and y on the mean are common
        curve = rng.integers(-3, 4, size=(2, K)).astype(float)
        chord = rng.integers(-3, 4, size=(2, 2)).astype(float)
        curve[0, rng.random(K) < rng.uniform(0.0, 1.0)] = np.nan
        chord[rng.random(2) < 0.5, 0] = np.nan
        if rng.random() < 0.2:  # symmetric about y = 0: the mean is 0, points on it
            curve[1] = np.where(np.arange(K) % 2 == 0, 1.0, -1.0) * np.abs(curve[1])
        w0 = rng.integers(-3, 4, size=2).astype(float)
        assert py_pick(curve, chord.copy(), w0) == _pick_reference(curve, chord, w0)


@settings(max_examples=300, **SETTINGS)
@given(
    kw=encounters(),
    reciprocal=st.booleans(),
    pz_buffer=st.sampled_from([0.0, 2.0]),
    horizon=st.sampled_from([None, 4.0]),
    inside=st.sampled_from(["no", "sphere", "prism"]),
    fast=st.floats(0.0, 12.0),
)
def test_the_preferred_shortcut_agrees_with_the_exact_check(
    kw: dict, reciprocal: bool, pz_buffer: float, horizon: float | None, inside: str, fast: float
) -> None:
    """The kernel returns the preferred velocity before building the cones' geometry when
    ``pref_clear`` says it is free: that must hold for the cones ``build_vos`` builds (exact 3D
    check, no zone A is inside) and be the same answer, also with A inside a neighbour's zone
    or an obstacle's prism, and with a cone left out for being out of reach (a neighbour flying
    away faster than v_max: ``fast`` sets one up; the aimed preferred velocity, within v_max,
    lies in no such cone)."""
    own, nbrs, obstacles = kw["own"], list(kw["neighbors"]), list(kw["obstacles"])
    if inside == "sphere":  # A inside the first neighbour's zone
        b = nbrs[0]
        nbrs[0] = Neighbor(position=own.position + [0.5 * b.r_pz, 0, 0], velocity=b.velocity,
                           r_pz=b.r_pz)
    elif inside == "prism":  # A inside a cylinder's prism
        obstacles.append(Cylinder(center=own.position[:2] + 1.0, radius=3.0,
                                  height=own.position[2] + 5.0))
    away = own.position + [0.0, 30.0, 0.0]  # receding at `fast`
    nbrs.append(Neighbor(position=away, velocity=[0.0, fast, 0.0], r_pz=3.0))
    options = Options(reciprocal=reciprocal, pz_buffer=pz_buffer, horizon=horizon)
    enc = prepare(own, kw["preferred_velocity"], nbrs, obstacles, kw["limits"], kw["dt"], options)
    clear = not (enc.unsafe(enc.v_pref)[0] or enc.vos.cones.inside.any()
                 or enc.vos.pyramids.inside.any())
    shortcut = py_pref_clear(
        np.asarray(own.position, float), np.asarray(own.velocity, float),
        np.asarray(kw["preferred_velocity"], float), neighbor_rows(nbrs), prism_rows(obstacles),
        Bounds.of(kw["limits"], kw["dt"]), options.config)
    assert shortcut == clear
    if inside != "no":
        assert not shortcut
