"""The closing guard (``closing_guard``): its rows against a brute-force build, and its promise
that two cooperative vehicles outside each other's zones are still outside after one step of
straight flight, whatever formulation decides (without it the same swarms do intrude)."""
from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt import Limits, VelocitySelector
from vo3d_opt.formulations.common import Bounds, Options, limit_rows

R_PZ, DT, V_MAX = 8.0, 0.2, 4.0
LIMITS = Limits(speed=(0.0, V_MAX), altitude=(0.0, 80.0))


def near_contact_swarm(seed: int, n: int = 5, side: float = 18.0):
    """n vehicles in a box so small that most pairs are within a step or two of each other's
    zones (none inside one), flying at random, each wanting to go to the swarm's centre."""
    rng = np.random.default_rng(seed)
    while True:
        P = rng.uniform(0.0, side, (n, 3))
        P[:, 2] += 20.0
        D = np.linalg.norm(P[:, None] - P[None], axis=-1) + np.eye(n) * 1e9
        if D.min() >= R_PZ:
            break
    V = rng.normal(size=(n, 3))
    V *= rng.uniform(0.0, V_MAX, (n, 1)) / np.linalg.norm(V, axis=1, keepdims=True)
    W = P.mean(axis=0) - P
    W *= V_MAX / np.linalg.norm(W, axis=1, keepdims=True)
    return P, V, W


def closest_after_one_step(sel: VelocitySelector, seed: int, limits: Limits = LIMITS) -> float:
    """The smallest pair distance minus r_pz after every vehicle flies its decision for dt."""
    P, V, W = near_contact_swarm(seed)
    many = sel.select_many(P, V, W, R_PZ, limits=limits, dt=DT, sensing_range=100.0)
    Q = P + many.velocities * DT
    D = np.linalg.norm(Q[:, None] - Q[None], axis=-1) + np.eye(len(P)) * 1e9
    return float(D.min() - R_PZ)


@pytest.mark.parametrize("reciprocal", [True, False])
def test_no_pair_enters_a_zone_within_the_step_and_without_the_guard_some_do(reciprocal):
    guarded = VelocitySelector(reciprocal=reciprocal, closing_guard=True)
    plain = VelocitySelector(reciprocal=reciprocal)
    seeds = range(60)
    assert min(closest_after_one_step(guarded, s) for s in seeds) >= -1e-9
    assert sum(closest_after_one_step(plain, s) < -1e-3 for s in seeds) >= 1


@pytest.mark.parametrize("formulation, solver, seeds", [
    ("plane_qp", "daqp", 15), ("cone_qp", "clarabel", 15), ("sampled", None, 4), ("nlp", None, 3)])
def test_every_formulation_keeps_the_guard(formulation, solver, seeds):
    kw = {} if solver is None else {"solver": solver}
    sel = VelocitySelector(formulation, **kw, reciprocal=True, closing_guard=True)
    assert min(closest_after_one_step(sel, s) for s in range(seeds)) >= -1e-9


def test_with_an_acceleration_limit_the_limits_hold():
    """The guard never asks for more braking than the acceleration box allows: every answer
    stays in the box (the guarantee itself then needs room to brake), and where a vehicle can
    brake to a hover within the step the pairs still stay out of each other's zones."""
    sel = VelocitySelector(reciprocal=True, closing_guard=True)
    for a in (2.0, 25.0):
        limits = Limits(speed=(0.0, V_MAX), altitude=(0.0, 80.0), acceleration=a)
        for seed in range(20):
            P, V, W = near_contact_swarm(seed)
            many = sel.select_many(P, V, W, R_PZ, limits=limits, dt=DT, sensing_range=100.0)
            assert np.all(np.abs(many.velocities - V) <= a * DT + 1e-6)
            if a * DT >= V_MAX:
                assert closest_after_one_step(sel, seed, limits) >= -1e-9


def brute_force_rows(p, v_now, nbrs, bounds: Bounds):
    """Rows u·v <= c of the cooperative neighbours whose c (half the gap over dt, no lower than
    u·v for the velocity of the acceleration box nearest hovering) is below v_max."""
    rows = []
    for x, y, z, vx, vy, vz, r, coop in nbrs:
        d = np.array([x, y, z]) - p
        if coop <= 0 or not np.linalg.norm(d) > 0:
            continue
        u = d / np.linalg.norm(d)
        c = 0.5 * max(np.linalg.norm(d) - r, 0.0) / bounds.dt
        if not np.isnan(bounds.acceleration):
            dv = bounds.acceleration * bounds.dt
            c = max(c, u @ np.clip(0.0, v_now - dv, v_now + dv))
        if c < bounds.v_max:
            rows.append([*u, c])
    return np.array(rows).reshape(-1, 4)


@pytest.mark.parametrize("acceleration", [None, 3.0])
def test_rows_against_brute_force(acceleration):
    rng = np.random.default_rng(5)
    on, off = Options(closing_guard=True).config, Options().config
    limits = Limits(speed=(0.0, V_MAX), altitude=(0.0, 80.0), acceleration=acceleration)
    bounds = Bounds.of(limits, DT)
    seen = 0
    for _ in range(200):
        p, v_now = rng.uniform(0, 20, 3) + [0, 0, 20], rng.normal(size=3)
        n = int(rng.integers(0, 6))
        nbrs = np.column_stack([p + rng.uniform(-12, 12, (n, 3)), rng.normal(size=(n, 3)),
                                np.full(n, R_PZ), rng.integers(0, 2, n)]).astype(float)
        G0, h0 = limit_rows(p, v_now, nbrs, bounds, off)
        G, h = limit_rows(p, v_now, nbrs, bounds, on)
        base = G0.shape[0]
        np.testing.assert_array_equal(G[:base], G0)
        np.testing.assert_array_equal(h[:base], h0)
        want = brute_force_rows(p, v_now, nbrs, bounds)
        np.testing.assert_allclose(np.column_stack([G[base:], h[base:]]), want, rtol=0, atol=1e-12)
        seen += len(want)
    assert seen > 50


def test_the_option_is_checked():
    with pytest.raises(ValueError, match="closing_guard"):
        VelocitySelector(closing_guard="yes")
