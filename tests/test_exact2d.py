"""exact2d, the exact per-plane solver: nearest point to w0 inside a disc (or annulus) and
half-planes. Checked on 10,000 random problems, degenerate ones included, against Clarabel with
the exact second-order cone and against an exact enumeration of the candidate optima."""
from __future__ import annotations

import itertools

import clarabel
import numpy as np
import pytest
import scipy.sparse as sp

from vo3d_opt.solvers import QP, get_backend
from vo3d_opt.solvers.exact2d import py_nearest_in_disc as nearest_in_disc
from vo3d_opt.status import Status

N_PROBLEMS = 10_000
TOL = 1e-9  # feasibility tolerance of the enumeration reference


def _solve(G, h, w0, r_max, r_min=0.0):
    out, order = np.empty(2), np.empty(max(len(h), 1), dtype=np.int64)
    ok = nearest_in_disc(np.ascontiguousarray(G, dtype=float).reshape(-1, 2), np.ascontiguousarray(h, dtype=float),
                         len(h), np.asarray(w0, dtype=float), r_max, r_min, order, out)
    return (out.copy() if ok else None)


def _feasible(w, G, h, r_max, r_min):
    n = np.linalg.norm(w)
    return n <= r_max + TOL and n >= r_min - TOL and np.all(G @ w <= h + TOL * (1 + np.abs(h)))


def _enumerate(G, h, w0, r_max, r_min=0.0):
    """The exact optimum by enumeration: with at most two active constraints in 2D it is w0
    itself, a projection onto one boundary (a line, the outer or the inner circle), or where two
    boundaries meet (two lines, a line and a circle); the nearest feasible candidate wins."""
    w0 = np.asarray(w0, dtype=float)
    cands = []
    n0 = np.linalg.norm(w0)
    unit = w0 / n0 if n0 > 0 else np.array([1.0, 0.0])
    cands += [w0, unit * r_max] + ([unit * r_min] if r_min > 0 else [])
    lines = [(g / np.linalg.norm(g), b / np.linalg.norm(g)) for g, b in zip(G, h) if np.linalg.norm(g) > 0]
    for n, d in lines:
        cands.append(w0 - (n @ w0 - d) * n)  # projection onto the line
        for r in (r_max, r_min):
            if r > 0 and abs(d) <= r + TOL:
                s = np.sqrt(max(r * r - d * d, 0.0))
                t = np.array([-n[1], n[0]])
                cands += [d * n + s * t, d * n - s * t]
    for (n1, d1), (n2, d2) in itertools.combinations(lines, 2):
        det = n1[0] * n2[1] - n1[1] * n2[0]
        if abs(det) > 1e-12:
            cands.append(np.array([d1 * n2[1] - d2 * n1[1], n1[0] * d2 - n2[0] * d1]) / det)
    feasible = [c for c in cands if _feasible(c, G, h, r_max, r_min)]
    if not feasible:
        return None
    return min(feasible, key=lambda c: np.linalg.norm(c - w0))


def _problem(rng: np.random.Generator):
    """A random plane problem; about half of them degenerate on purpose."""
    r = float(rng.uniform(0.5, 6.0))
    m = int(rng.integers(0, 8))
    G = rng.normal(size=(m, 2))
    h = rng.uniform(-1.2, 1.2, m) * r * np.linalg.norm(G, axis=1)
    kind = rng.integers(0, 8)
    if kind == 1 and m >= 2:  # parallel lines, same or opposite normals
        G[1] = G[0] * rng.choice([-2.0, 0.5, 1.0])
    if kind == 2 and m >= 2:  # coincident lines
        G[1], h[1] = G[0], h[0]
    if kind == 3 and m >= 1:  # a line tangent to the disc, from either side
        h[0] = rng.choice([-1.0, 1.0]) * r * np.linalg.norm(G[0])
    if kind == 4 and m >= 2:  # an empty set: two opposite half-planes with a gap
        G[1], h[1] = -G[0], -h[0] - 0.5 * np.linalg.norm(G[0])
    if kind == 5 and m >= 1:  # a row with no normal (0 <= h or nothing)
        G[0] = 0.0
    w0 = rng.normal(size=2) * r * rng.choice([0.3, 1.0, 2.5])
    if kind == 6:
        w0[:] = 0.0  # w0 at the origin
    if kind == 7 and m >= 1:  # w0 exactly on a line
        g = G[0] / np.linalg.norm(G[0])
        w0 = w0 - (g @ w0 - h[0] / np.linalg.norm(G[0])) * g
    return G, h, w0, r


def test_agrees_with_exact_enumeration_on_10000_problems():
    rng = np.random.default_rng(2026)
    infeasible = degenerate = 0
    for _ in range(N_PROBLEMS):
        G, h, w0, r = _problem(rng)
        got, ref = _solve(G, h, w0, r), _enumerate(G, h, w0, r)
        assert (got is None) == (ref is None), (G, h, w0, r)
        if got is None:
            infeasible += 1
            continue
        assert np.linalg.norm(got - w0) == pytest.approx(np.linalg.norm(ref - w0), abs=1e-7)
        assert _feasible(got, G, h, r, 0.0)
    assert infeasible > 200  # the empty sets were exercised


def _clarabel(G, h, w0, r):
    """Clarabel on the problem with the speed bound as an exact second-order cone, at tight
    tolerances (1e-15: its answers are then accurate to about 1e-13 when it reports them
    solved; the backend's own 1e-10 gives about 1e-5 with the cone active)."""
    P, q = sp.csc_matrix(2 * np.eye(2)), -2 * np.asarray(w0, dtype=float)
    A = sp.csc_matrix(np.vstack([np.reshape(G, (-1, 2)), np.zeros((1, 2)), -np.eye(2)]))
    b = np.concatenate([h, [r], np.zeros(2)])
    cones = ([clarabel.NonnegativeConeT(len(h))] if len(h) else []) + [clarabel.SecondOrderConeT(3)]
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-15
    settings.tol_ktratio, settings.max_iter = 1e-12, 400
    sol = clarabel.DefaultSolver(P, q, A, b, cones, settings).solve()
    return str(sol.status), np.array(sol.x)


def test_agrees_with_clarabel_on_10000_problems():
    """The same feasibility verdict as Clarabel with the exact cone on every problem, and the
    same optimum within 1e-7 m/s wherever Clarabel reports it solved to its tolerances (on sets
    with no interior, such as a single tangent point, an interior-point method stops 'almost'
    solved: those are checked by the enumeration test)."""
    rng = np.random.default_rng(7)
    compared = 0
    for _ in range(N_PROBLEMS):
        G, h, w0, r = _problem(rng)
        status, x = _clarabel(G, h, w0, r)
        got = _solve(G, h, w0, r)
        assert (got is None) == (status == "PrimalInfeasible"), (G, h, w0, r, status)
        if got is not None and status == "Solved":
            compared += 1
            assert np.linalg.norm(got - x) <= 1e-7
    assert compared > 1500


def test_annulus():
    """v_min > 0: the inner disc excluded. Against the enumeration, which also covers the
    inner circle."""
    rng = np.random.default_rng(3)
    for _ in range(2000):
        G, h, w0, r = _problem(rng)
        r_min = float(rng.uniform(0.0, 0.9)) * r
        got, ref = _solve(G, h, w0, r, r_min), _enumerate(G, h, w0, r, r_min)
        assert (got is None) == (ref is None), (G, h, w0, r, r_min)
        if got is not None:
            assert np.linalg.norm(got - w0) == pytest.approx(np.linalg.norm(ref - w0), abs=1e-7)
            assert r_min - 1e-9 <= np.linalg.norm(got) <= r + 1e-9


def test_backend_interface():
    """As a registered backend: 2-variable QPs with P = c I; anything else is 'failed'."""
    b = get_backend("exact2d")
    res = b.solve(QP(P=4 * np.eye(2), q=np.array([-8.0, 0.0]), G=np.array([[1.0, 0.0]]), h=np.array([1.0]),
                     soc_radius=3.0))
    assert res.status == Status.OPTIMAL and np.allclose(res.x, [1.0, 0.0])
    assert b.solve(QP(P=np.diag([1.0, 2.0]), q=np.zeros(2))).status == Status.FAILED
    assert b.solve(QP(P=np.eye(3), q=np.zeros(3))).status == Status.FAILED
    assert b.solve(QP(P=2 * np.eye(2), q=np.zeros(2), G=np.array([[1.0, 0.0], [-1.0, 0.0]]),
                      h=np.array([-1.0, -1.0]))).status == Status.INFEASIBLE
