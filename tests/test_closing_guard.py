"""The closing guard (``closing_guard``): its rows against a brute-force build, and its promise
that two cooperative vehicles outside each other's zones are still outside after one step of
straight flight, whatever formulation decides (without it the same swarms do intrude)."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from vo3d_opt import Limits, VelocitySelector
from vo3d_opt.formulations.common import LIMIT_TOL, Bounds, Options, limit_rows
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import bundled_files, scenario_from_dict
from vo3d_opt.sim.simulator import run_scenario, scenario_selector

R_PZ, DT, V_MAX = 8.0, 0.2, 4.0
LIMITS = Limits(speed=(0.0, V_MAX), altitude=(0.0, 80.0))
#: Each guard row holds to the limits' tolerance, so a pair may close this much more (m).
SLACK = 2 * LIMIT_TOL * DT


def pair_distances(X: np.ndarray) -> np.ndarray:
    """(n, n) distances between the rows of X, a huge number on the diagonal (no self-pairs)."""
    return np.linalg.norm(X[:, None] - X[None], axis=-1) + np.eye(len(X)) * 1e9


def near_contact_swarm(seed: int, n: int = 5, side: float = 18.0, inside: bool = False
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n vehicles in a box so small that some pairs are within a step of each other's zones
    (with ``inside`` one pair starts inside, else none), flying at random, each wanting to go
    to the swarm's centre: positions, velocities, preferred velocities (n, 3)."""
    rng = np.random.default_rng(seed)
    while True:
        P = rng.uniform(0.0, side, (n, 3))
        P[:, 2] += 20.0
        D = pair_distances(P)
        if inside:
            unit = rng.normal(size=3)
            P[1] = P[0] + unit / np.linalg.norm(unit) * rng.uniform(4.0, 7.5)
            D = pair_distances(P)
            D[0, 1] = D[1, 0] = np.inf
        if D.min() >= R_PZ:
            break
    V = rng.normal(size=(n, 3))
    V *= rng.uniform(0.0, V_MAX, (n, 1)) / np.linalg.norm(V, axis=1, keepdims=True)
    W = P.mean(axis=0) - P
    W *= V_MAX / np.linalg.norm(W, axis=1, keepdims=True)
    return P, V, W


def one_step(sel: VelocitySelector, seed: int, limits: Limits = LIMITS, inside: bool = False):
    """Every vehicle of ``near_contact_swarm(seed)`` decides (all see all) and flies its answer
    for dt: the swarm, the decisions, and the pair distances before and after (n, n)."""
    P, V, W = near_contact_swarm(seed, inside=inside)
    many = sel.select_many(P, V, W, R_PZ, limits=limits, dt=DT, sensing_range=100.0)
    Q = P + many.velocities * DT
    before = pair_distances(P)
    after = pair_distances(Q)
    return (P, V, W), many, before, after


def closest_after_one_step(sel: VelocitySelector, seed: int) -> float:
    """The smallest pair distance minus r_pz after one step."""
    return float(one_step(sel, seed)[3].min() - R_PZ)


@pytest.mark.parametrize("reciprocal", [True, False])
def test_no_pair_enters_a_zone_within_the_step_and_without_the_guard_some_do(reciprocal):
    guarded = VelocitySelector(preset="paper", reciprocal=reciprocal, closing_guard=True)
    plain = VelocitySelector(preset="paper", reciprocal=reciprocal)
    seeds = range(60)
    assert min(closest_after_one_step(guarded, s) for s in seeds) >= -SLACK
    assert sum(closest_after_one_step(plain, s) < -1e-3 for s in seeds) >= 1


@pytest.mark.parametrize("gap", [0.05, 0.5])
def test_the_least_bad_fallback_keeps_the_guard_too(gap):
    """A vehicle boxed in by six others (an octahedron, each ``gap`` m from its zone), all
    flying at it: the centre has no safe velocity (least-bad fallback), and still no pair
    enters a zone within the step."""
    sel = VelocitySelector(preset="paper", reciprocal=True, closing_guard=True)
    axes = np.vstack([np.eye(3), -np.eye(3)])
    P = np.vstack([[0.0, 0.0, 30.0], [0.0, 0.0, 30.0] + (R_PZ + gap) * axes])
    V = np.vstack([[0.0, 0.0, 0.0], -2.0 * axes])
    W = np.vstack([[V_MAX, 0.0, 0.0], -V_MAX * axes])
    many = sel.select_many(P, V, W, R_PZ, limits=LIMITS, dt=DT, sensing_range=100.0)
    assert many.statuses[0] == "infeasible_min_violation"
    Q = P + many.velocities * DT
    after = pair_distances(Q)
    assert after.min() >= R_PZ - SLACK


def test_a_pair_inside_a_zone_does_not_close_in():
    sel = VelocitySelector(preset="paper", reciprocal=True, closing_guard=True)
    for seed in range(20):
        _, _, before, after = one_step(sel, seed, inside=True)
        assert before[0, 1] < R_PZ and after[0, 1] >= before[0, 1] - SLACK
        others = before >= R_PZ
        assert np.all(after[others] >= R_PZ - SLACK)


@pytest.mark.parametrize("formulation, solver, seeds", [
    ("plane_qp", "daqp", 15), ("cone_qp", "clarabel", 15), ("sampled", None, 4), ("nlp", None, 3)])
def test_every_formulation_keeps_the_guard(formulation, solver, seeds):
    kw = {} if solver is None else {"solver": solver}
    sel = VelocitySelector(formulation, **kw, reciprocal=True, closing_guard=True)
    assert min(closest_after_one_step(sel, s) for s in range(seeds)) >= -SLACK


def brake_point(v_now: np.ndarray, dv: float) -> np.ndarray:
    """The velocity of the box |v - v_now| <= dv (per axis) nearest hovering."""
    return np.clip(0.0, v_now - dv, v_now + dv)


@pytest.mark.parametrize("formulation, solver", [("plane_qp", None), ("cone_qp", "clarabel")])
def test_with_an_acceleration_limit_every_limit_holds_and_unraised_pairs_stay_out(formulation, solver):
    """Every answer meets its limit rows (the box and the guard's), and every pair whose rows
    were not raised to the box's braking point (both can brake enough) stays out of its zone."""
    kw = {} if solver is None else {"solver": solver}
    sel = VelocitySelector(formulation, **kw, reciprocal=True, closing_guard=True)
    cfg, a = Options(reciprocal=True, closing_guard=True).config, 2.0
    limits = Limits(speed=(0.0, V_MAX), altitude=(0.0, 80.0), acceleration=a)
    bounds, checked = Bounds.of(limits, DT), 0
    for seed in range(12 if solver is None else 4):
        (P, V, W), many, before, after = one_step(sel, seed, limits)
        n = len(P)
        for i in range(n):
            nbrs = np.array([[*P[j], *V[j], R_PZ, 1.0] for j in range(n) if j != i])
            G, h = limit_rows(P[i], V[i], nbrs, bounds, cfg)
            assert np.all(G @ many.velocities[i] <= h + LIMIT_TOL)
        for i in range(n):
            for j in range(i + 1, n):
                u = (P[j] - P[i]) / before[i, j]
                c = 0.5 * (before[i, j] - R_PZ) / DT
                if u @ brake_point(V[i], a * DT) <= c and -u @ brake_point(V[j], a * DT) <= c:
                    assert after[i, j] >= R_PZ - SLACK
                    checked += 1
    assert checked > 20


def test_the_option_reaches_a_scenario_run():
    """``selector_options: {closing_guard: true}`` in a scenario: the run's selector has it, and
    the bundled 16-agent sphere swap stays clear."""
    path = next(p for p in bundled_files() if p.stem == "sphere-swap-16")
    data = yaml.safe_load(path.read_text())
    data["selector_options"] = {**data.get("selector_options", {}), "closing_guard": True}
    sc = scenario_from_dict(data)
    assert scenario_selector(sc)[0].config.safety.closing_guard
    s = summarize(run_scenario(sc, progress=False))
    assert s["pz_intrusions"] == 0 and s["collisions"] == 0 and s["all_reached"]


def brute_force_rows(p: np.ndarray, v_now: np.ndarray, nbrs: np.ndarray, bounds: Bounds) -> np.ndarray:
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
            c = max(c, u @ brake_point(v_now, bounds.acceleration * bounds.dt))
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
        if acceleration is not None:  # the box's braking point meets every row
            assert np.all(G @ brake_point(v_now, acceleration * DT) <= h + 1e-12)
    assert seen > 50


def test_the_option_is_checked():
    with pytest.raises(ValueError, match="closing_guard"):
        VelocitySelector(closing_guard="yes")
