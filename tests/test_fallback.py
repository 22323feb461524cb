"""The least-bad fallback against a plain numpy reference: among its candidates (the tried
answers, the grid on every plane, zero, v_now; with an acceleration limit all of them again
clipped into the reachable box) within the limits, the latest first intrusion, ties at once
(inside zones) slowest closing on them first (``least_bad_escape``, the default), then nearest
the preferred velocity, the first such candidate in that order."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from encounters import crowd, encounters
from vo3d_opt import AgentState, Limits, Neighbor
from vo3d_opt.formulations.common import (
    NEVER,
    Options,
    _zone_time,
    prepare,
    py_decision_planes,
    zone_time_bound,
)
from vo3d_opt.formulations.fallback import (
    first_safe,
    grid_of,
    py_fallback,
    py_least_bad,
    py_polar_grid,
)
from vo3d_opt.formulations.kernel import py_plane_qps, py_search
from vo3d_opt.geometry.membership import ball_in_cone, in_vo_cones

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)

def _grid_of(bounds, cfg):
    return grid_of(bounds, cfg, False)


def _block_covered(cones, to_plane, discs, b, p):
    c = discs[b, 0] * to_plane[0, 0] + discs[b, 1] * to_plane[p, 1]
    return any(ball_in_cone(cones, k, c, discs[b, 2]) for k in range(cones.d_oi.shape[0]))


def _candidates(enc, planes, tried, grid):
    """The candidates of least_bad, in its order (each pass)."""
    on_planes = [grid[:, :1] * planes.to_plane[p, 0] + grid[:, 1:] * planes.to_plane[p, 1]
                 for p in range(len(planes.phi))]
    first = np.vstack([tried, *on_planes, np.zeros((1, 3)), np.asarray(enc.v_now)[None]])
    if enc.limits.acceleration is None:
        return first
    dv = enc.limits.acceleration * enc.dt
    return np.vstack([first, np.clip(first, enc.v_now - dv, enc.v_now + dv)])


def _reference(enc, planes, tried):
    cfg = enc.options.config
    cands = _candidates(enc, planes, tried, py_polar_grid(enc.bounds, cfg))
    ok = enc.within_limits(cands)
    t = np.minimum(enc.time_to_intrusion(cands), NEVER)
    dev = np.linalg.norm(cands - enc.v_pref, axis=1)
    # least_bad_escape: among velocities entering a zone at once, the slowest closing first
    cl = np.where(t == 0.0, enc.closing_rate(cands), 0.0) if cfg.least_bad_escape else 0.0 * t
    best = min(np.flatnonzero(ok), key=lambda i: (-t[i], cl[i], dev[i], i), default=None)
    return None if best is None else (cands[best], t[best], dev[best])


@settings(max_examples=40, **SETTINGS)
@given(kw=encounters(max_neighbors=15), accel=st.one_of(st.none(), st.floats(0.5, 6.0)),
       n_tried=st.integers(0, 12), seed=st.integers(0, 2**16), escape=st.booleans())
def test_least_bad_is_the_latest_intrusion(kw, accel, n_tried, seed, escape):
    rng = np.random.default_rng(seed)
    v_max = kw["limits"].speed[1]
    v_now = rng.uniform(-1, 1, 3) * v_max / 2  # not v_pref: the clipped pass then differs
    limits = Limits(speed=kw["limits"].speed, altitude=kw["limits"].altitude, acceleration=accel)
    own = AgentState(position=kw["own"].position, velocity=v_now)
    enc = prepare(own, np.asarray(kw["preferred_velocity"]), kw["neighbors"], kw["obstacles"],
                  limits, kw["dt"], Options(least_bad_escape=escape))
    planes = py_decision_planes(enc.vos, enc.v_now, enc.options.config)
    tried = np.ascontiguousarray(rng.uniform(-v_max, v_max, (n_tried, 3)))
    G3, h3 = enc.linear_bounds()
    got = py_least_bad(enc.vos, planes, tried, np.asarray(enc.position, float), enc.v_now, G3, h3,
                       enc.bounds, enc.options.config)
    ref = _reference(enc, planes, tried)
    assert ref is not None  # zero or a grid point is always within these limits
    v, t, dev = ref
    # the same key; the same velocity up to rounding (duplicate grid points on e1 tie exactly)
    assert min(enc.time_to_intrusion(got)[0], NEVER) == t
    assert abs(np.linalg.norm(got - enc.v_pref) - dev) <= 1e-12
    np.testing.assert_allclose(got, v, atol=1e-9)


# ------------------------------------------------------------- the grid's blocks, in a crowd

def _grid_reference(enc, planes, grid):
    """grid_search in plain numpy: points in order of deviation (ties within 1e-12 plane by
    plane, then in grid order), on e1 on plane 0 only; the first that ``first_safe`` (point
    by point, no blocks) accepts."""
    w0 = planes.to_plane[0, 0] @ enc.v_pref
    dev = np.sqrt((grid[:, 0] - w0) ** 2 + grid[:, 1] ** 2)
    order = np.argsort(dev, kind="mergesort")
    cands, where = [], []
    a = 0
    while a < len(order):
        b = a
        while b < len(order) and dev[order[b]] <= dev[order[a]] + 1e-12:
            b += 1
        for p in range(len(planes.phi)):
            for g in order[a:b]:
                if grid[g, 1] == 0.0 and p > 0:
                    continue
                cands.append(grid[g, 0] * planes.to_plane[0, 0] + grid[g, 1] * planes.to_plane[p, 1])
                where.append(p)
        a = b
    k = first_safe(enc, np.array(cands))
    return (False, -1) if k is None else (True, where[k], cands[k])


@pytest.mark.parametrize("seed", range(40))
def test_fallbacks_with_blocks_are_the_point_by_point_answers(seed):
    """In crowds (most points decided by their block) grid_search returns the reference's point
    and plane, least_bad the reference's key and velocity; with and without a horizon (which
    turns the grid's blocks off: 1–8 s), with an acceleration limit (least_bad's clipped pass,
    where no block is skipped), with A inside a zone (a VO no block lies in)."""
    for case in range(5 * seed, 5 * seed + 5):  # 200 crowds in all
        _check_fallbacks(case)


@pytest.mark.parametrize("seed", range(20))
def test_fallbacks_in_a_swap_centre_are_the_point_by_point_answers(seed):
    """As above, in crowds like the sphere swap's centre: 20–79 neighbours all closing in, with
    the swap's options (reciprocal, the zones widened by 1.6 m), where most decisions end
    least-bad and the best time so far lets least_bad skip blocks often; a third with an
    acceleration limit. (Skipping blocks whose bound is only below 1.5 x the best time changes
    answers here, and not in the crowds above; so does skipping in the clipped pass.)"""
    for case in range(5 * seed, 5 * seed + 5):  # 100 crowds in all
        kw = crowd(1000 + case, n=20 + case % 60, closing=3.0)
        _checkcrowd(case, kw, Options(reciprocal=True, pz_buffer=1.6),
                     accel=3.0 if case % 3 == 2 else None)


def test_closing_rate_is_the_fastest_closing_on_the_zones_inside():
    """``closing_rate`` against numpy: over the neighbours whose (planning) zone holds the
    vehicle, the largest rel·(v − apex) / d_oi, 0 when none closes; the others do not count."""
    rng = np.random.default_rng(5)
    for case in range(20):
        kw = crowd(3000 + case, n=12, inside=True, closing=1.0)
        enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"]), kw["neighbors"], [],
                      kw["limits"], kw["dt"], Options(reciprocal=bool(case % 2), pz_buffer=2.0))
        c = enc.vos.cones
        assert c.inside.any() and not c.inside.all()
        v = rng.uniform(-4.0, 4.0, (50, 3))
        rates = ((v[:, None, :] - c.apex[None]) * c.rel[None]).sum(-1) / c.d_oi[None]
        want = np.maximum(np.where(c.inside[None], rates, -np.inf).max(axis=1), 0.0)
        np.testing.assert_allclose(enc.closing_rate(v), want, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_least_bad_escape_inside_zones_is_the_point_by_point_answer(seed):
    """With ``least_bad_escape`` (the default), in swap-centre crowds where the vehicle is
    inside a zone and every velocity enters one at once: the reference's velocity (slowest
    closing on the zones it is inside, then nearest v_pref), blocks and all; without it, the
    reference's too (nearest v_pref); some answers differ, the default's closing slower."""
    slower = 0
    for case in range(5 * seed, 5 * seed + 5):  # 40 crowds in all
        kw = crowd(2000 + case, n=30 + case % 40, inside=True, closing=3.0)
        accel = 3.0 if case % 4 == 3 else None
        default = Options(reciprocal=True, pz_buffer=1.6)
        assert default.least_bad_escape  # the default since the whole N = 10,000 swap
        got, enc = _checkcrowd(case, kw, default, accel)
        nearest = Options(reciprocal=True, pz_buffer=1.6, least_bad_escape=False)
        plain, _ = _checkcrowd(case, kw, nearest, accel)
        if got is not None and plain is not None:
            c_got, c_plain = enc.closing_rate(np.array([got, plain]))
            assert c_got <= c_plain + 1e-12
            slower += c_got < c_plain - 1e-9
    assert slower > 0


def _check_fallbacks(seed):
    kw = crowd(seed, n=20 + seed % 24, inside=seed % 4 == 3, closing=(0.0, 3.0)[seed % 3 == 0])
    horizon = (None, None, 8.0, None, 2.0, 1.0)[seed % 6]
    _checkcrowd(seed, kw, Options(horizon=horizon), accel=3.0 if seed % 5 == 4 else None)


def _checkcrowd(seed, kw, options, accel):
    """py_fallback on crowd ``kw`` against the numpy references (``seed``: its tried answers);
    returns the least-bad velocity (None when the grid found a safe one) and the encounter."""
    limits = Limits(speed=kw["limits"].speed, altitude=kw["limits"].altitude, acceleration=accel)
    own = AgentState(position=kw["own"].position,
                     velocity=np.asarray(kw["preferred_velocity"]) * (0.5 if accel else 1.0))
    enc = prepare(own, np.asarray(kw["preferred_velocity"]), kw["neighbors"], [],
                  limits, kw["dt"], options)
    cfg = enc.options.config
    planes = py_decision_planes(enc.vos, enc.v_now, cfg)
    G3, h3 = enc.linear_bounds()
    rng = np.random.default_rng(seed)
    if seed % 2:  # random tried answers, or the QP search's, as the kernel passes them
        tried = np.ascontiguousarray(rng.uniform(-4.0, 4.0, (8, 3)))
    else:
        qps = py_plane_qps(enc.vos, planes, G3, h3, enc.pref_in | enc.inside, cfg, True)
        R, P = qps.key.shape
        tried = np.empty((R * P * (len(enc.pref_in) + 1), 3))
        n_tried = py_search(qps, enc.bounds, tried)[3]
        tried = np.ascontiguousarray(tried[:n_tried])
    position = np.asarray(enc.position, float)
    found, v, p = py_fallback(enc.vos, planes, tried, position, enc.v_now, G3, h3, enc.bounds, cfg,
                              False)
    ref = _grid_reference(enc, planes, py_polar_grid(enc.bounds, cfg))
    assert found == ref[0]
    v_ref, t_ref, dev_ref = _reference(enc, planes, tried)
    # least_bad alone (no cones known to hold the blocks), and after grid_search when it found
    # nothing (with the cones it found)
    answers = [py_least_bad(enc.vos, planes, tried, position, enc.v_now, G3, h3, enc.bounds, cfg)]
    if found:
        assert p == ref[1]
        np.testing.assert_array_equal(v, ref[2])
    else:
        answers.append(v)
    for got in answers:
        assert min(enc.time_to_intrusion(got)[0], NEVER) == t_ref
        assert abs(np.linalg.norm(got - enc.v_pref) - dev_ref) <= 1e-12
        np.testing.assert_allclose(got, v_ref, atol=1e-9)
    return (None if found else answers[0]), enc


def test_the_crowds_use_the_blocks():
    """The crowds above are ones where blocks decide: most grid points on most planes lie in a
    VO cone's block (else the test above would not test them); the grid finds a safe velocity
    in some of them and none in others (the least-bad fallback)."""
    covered, found = [], []
    for seed in range(24):
        kw = crowd(seed, n=20 + seed, inside=seed % 4 == 3)
        enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"]), kw["neighbors"], [],
                      kw["limits"], kw["dt"], Options())
        planes = py_decision_planes(enc.vos, enc.v_now, enc.options.config)
        grid = _grid_of(enc.bounds, enc.options.config)
        covered.append(np.mean([_block_covered(enc.vos.cones, planes.to_plane, grid.discs, b, p)
                                for p in range(len(planes.phi)) for b in range(len(grid.discs))]))
        G3, h3 = enc.linear_bounds()
        found.append(py_fallback(enc.vos, planes, np.zeros((0, 3)), np.asarray(enc.position, float),
                                 enc.v_now, G3, h3, enc.bounds, enc.options.config, False)[0])
    assert np.mean(covered) > 0.5 and 0 < sum(found) < len(found)


# ------------------------------------------- the blocks' certificates against brute force

def _zone_times(vos, k, v):
    return np.array([_zone_time(vos, k, x) for x in np.asarray(v, dtype=float)])


_time_bound = zone_time_bound
_ball_in = ball_in_cone


def _ball_points(rng, c, rho, m=400, worst=None):
    """m velocities in the ball of radius rho about c, half of them on its surface; with
    ``worst`` (apex, rel) also the ball's points that certificates find hardest: farthest
    from rel's direction seen from the apex, and c - rho rel/|rel| (least rel·u)."""
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    r = np.where(np.arange(m) % 2 == 0, rho, rho * rng.uniform(0, 1, m) ** (1 / 3))
    pts = c + d * r[:, None]
    if worst is not None:
        apex, rel = worst
        axis, u = rel / np.linalg.norm(rel), c - apex
        away = u / np.linalg.norm(u) - axis  # in the plane of u and rel, away from rel
        if np.linalg.norm(away) > 0:
            away /= np.linalg.norm(away)
            pts = np.vstack([pts, c + rho * away, c - rho * axis])
    return np.ascontiguousarray(pts)


def _bisect(accepts, lo=0.0, hi=10.0, steps=60):
    """The largest radius (to 2^-60 of hi) that ``accepts`` takes, or 0."""
    if not accepts(hi * 2.0**-steps):
        return 0.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if accepts(mid) else (lo, mid)
    return lo


@pytest.mark.parametrize("seed", range(6))
def test_block_certificates_hold_for_every_velocity_of_the_ball(seed):
    """Whenever ``ball_in_cone`` certifies a ball, the exact membership (as computed) holds at
    each of 400 of its velocities (half on its surface); whenever ``zone_time_bound`` gives a
    time, the zone time (as computed) is at most that at each of them. Balls from deep inside
    to far outside the cone, of every size: both certificates certify some and refuse some,
    and the time bound is tight within a factor 3 on some (it bounds something)."""
    rng = np.random.default_rng(seed)
    kw = crowd(seed, n=12, inside=seed == 5)
    enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"]), kw["neighbors"], [],
                  kw["limits"], kw["dt"], Options())
    cones = enc.vos.cones
    certified = refused = timed = tight = 0
    for _ in range(300):
        k = int(rng.integers(cones.d_oi.shape[0]))
        axis = cones.rel[k] / np.linalg.norm(cones.rel[k])
        # a centre about the axis (near it, or anywhere), at 0.2–8 m/s from the apex
        off = rng.normal(size=3) * rng.choice([0.05, 0.3, 1.0])
        c = cones.apex[k] + (axis + off) / np.linalg.norm(axis + off) * rng.uniform(0.2, 8.0)
        rho = float(rng.choice([1e-6, 0.05, 0.5, 2.0]) * rng.uniform(0.5, 1.0))
        pts = _ball_points(rng, c, rho, worst=(cones.apex[k], cones.rel[k]))
        if _ball_in(cones, k, c, rho):
            certified += 1
            assert in_vo_cones(cones, pts)[k].all()
        else:
            refused += 1
        bound = _time_bound(enc.vos, k, c, rho)
        if bound < np.inf:
            timed += 1
            times = _zone_times(enc.vos, k, pts)
            assert (times <= bound).all()
            tight += times.max() >= bound / 3
    assert refused > 0 and (seed == 5 or (certified > 0 and timed > 0 and tight > 0))


def test_time_bound_near_a_tangent_holds_as_computed():
    """A vehicle 1.5e-12 m outside a zone and a velocity ball grazing it: the root's argument
    pu^2 - |u|^2 Q is of the order of its rounding (pu's terms cancel), and one velocity of the
    ball (exactly within rho) is computed never to enter. The bound must then be inf, not a
    time (a fresh reviewer's case)."""
    from vo3d_opt.formulations.common import VOs
    from vo3d_opt.geometry import VOPyramids
    from vo3d_opt.geometry.cone import vo_cones

    rel = np.array([-37.91702773376036, 18.35885856840399, 41.07263569166567])
    apex = np.array([-0.022728666465307645, 0.16346027022509538, 0.004123117819953033])
    cones = vo_cones(np.zeros(3), rel[None], apex[None], 58.83629902328598, virtual_sphere=False)
    vos = VOs(cones, VOPyramids.empty(), np.zeros(3))
    c = np.array([26.799554736298717, -24.69884877053471, 35.878752010620246])
    v = np.array([26.79955473694235, -24.698848770846762, 35.87875200992142])
    rho = 1e-9
    assert np.linalg.norm(v - c) <= rho and _zone_times(vos, 0, v[None])[0] == np.inf
    assert _time_bound(vos, 0, c, rho) == np.inf
    rng = np.random.default_rng(0)
    for scale in (1e-9, 1e-7, 1e-5, 1e-3):  # balls about c, of every size: none may lie
        for _ in range(50):
            cc = c + rng.normal(size=3) * scale
            bound = _time_bound(vos, 0, cc, scale)
            if bound < np.inf:
                assert (_zone_times(vos, 0, _ball_points(rng, cc, scale)) <= bound).all()


@pytest.mark.parametrize("seed", range(4))
def test_block_certificates_hold_at_their_largest_ball(seed):
    """The largest ball each certificate takes about a centre (found by bisection: the ball
    on the edge of the margins), with its hardest points: ``in_cone`` and the zone time, as
    computed, still hold at every one."""
    rng = np.random.default_rng(100 + seed)
    kw = crowd(seed, n=12)
    enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"]), kw["neighbors"], [],
                  kw["limits"], kw["dt"], Options())
    cones = enc.vos.cones
    edges = 0
    for _ in range(60):
        k = int(rng.integers(cones.d_oi.shape[0]))
        axis = cones.rel[k] / np.linalg.norm(cones.rel[k])
        off = rng.normal(size=3) * rng.choice([0.05, 0.2])
        c = cones.apex[k] + (axis + off) / np.linalg.norm(axis + off) * rng.uniform(0.5, 8.0)
        worst = (cones.apex[k], cones.rel[k])
        rho = _bisect(lambda r: _ball_in(cones, k, c, r))
        if rho > 0:
            edges += 1
            assert in_vo_cones(cones, _ball_points(rng, c, rho, worst=worst))[k].all()
        rho = _bisect(lambda r: _time_bound(enc.vos, k, c, r) < np.inf)
        if rho > 0:
            edges += 1
            pts = _ball_points(rng, c, rho, worst=worst)
            assert (_zone_times(enc.vos, k, pts) <= _time_bound(enc.vos, k, c, rho)).all()
    assert edges > 20


def _near_surfaces(rng: np.random.Generator, cones, m: int) -> np.ndarray:
    """m velocities about the cones' surfaces: each a generator's direction (tangent to the
    zone) turned a little in or out, at 0.1-8 m/s from that cone's apex; and m behind the
    cones' apexes, h = 1e-9 to 1 m/s behind (where a cone next to its zone is almost flat)."""
    out = np.empty((2 * m, 3))
    for j in range(2 * m):
        k = int(rng.integers(cones.d_oi.shape[0]))
        axis = cones.rel[k] / cones.d_oi[k]
        side = np.cross(axis, rng.normal(size=3))
        side /= np.linalg.norm(side)
        if j < m:
            half = np.arcsin(min(cones.sin_alpha[k], 1.0)) * rng.uniform(0.0, 2.5)
            turn = np.cos(half) * axis + np.sin(half) * side
            out[j] = cones.apex[k] + turn * rng.uniform(0.1, 8)
        else:
            behind = 10.0 ** rng.uniform(-9, 0)
            out[j] = cones.apex[k] + side * rng.uniform(0, 4) - axis * behind
    return out


#: How far outside its zone (r_pz 5 m) the neighbour next to it is: one ulp, 1e-12 m, 1e-6 and
#: 1e-5 of the distance, and 0.3 m (with a buffer of 1.6 m it then takes 90 % of the gap, and
#: the answer is asked to open it: the apex moves).
EDGES = (float(np.nextafter(5.0, np.inf)), 5.0 + 1e-12, 5.0 * (1 + 1e-6), 5.0 * (1 + 1e-5), 5.3)


def _next_to_zone(seed: int, d: float) -> dict:
    """A crowd of four with a fifth neighbour d m away (its zone r_pz 5 m)."""
    kw = crowd(seed, n=4)
    rng = np.random.default_rng(seed)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    kw["neighbors"].append(Neighbor(position=np.asarray(kw["own"].position) + d * u,
                                    velocity=rng.normal(size=3), r_pz=5.0))
    return kw


@pytest.mark.parametrize("seed", range(4 + len(EDGES)))
def test_clearance_floor_bounds_each_cones_clearance(seed):
    """The margin check skips clearance's search for a cone whose closed-form floor already
    clears the margin; the floor must then lie below that cone's clearance as computed, with
    or without a horizon, next to a zone too, and be close to it often enough to skip
    something."""
    from vo3d_opt.geometry import VOPyramids, clearance_floors, clearances

    rng = np.random.default_rng(seed)
    kw = (_next_to_zone(seed, EDGES[seed - 4]) if seed >= 4
          else crowd(seed, n=10, inside=seed == 3, closing=2.0 * (seed % 2)))
    enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"]), kw["neighbors"], [],
                  kw["limits"], kw["dt"], Options(reciprocal=True, pz_buffer=1.6))
    cones = enc.vos.cones
    v = np.vstack([_near_surfaces(rng, cones, 200), rng.uniform(-4, 4, (100, 3))])
    floors = clearance_floors(cones, v)
    close = 0
    for k in range(cones.d_oi.shape[0]):
        if cones.inside[k]:
            assert (floors[k] == -np.inf).all()
            continue
        one = cones.subset(np.array([k]))
        for horizon in (None, 1.0, 6.0):
            exact = clearances(one, VOPyramids.empty(), v, horizon=horizon)
            assert (floors[k] <= exact).all()
            close += int(((floors[k] >= 0.5 * exact) & (exact > 1e-3)).sum())
    assert close > 100


def _margins_about(c: float) -> tuple[float, float]:
    """The largest margin the check must accept at clearance c (margin (1 - 1e-9) <= c) and
    the next float above it, which it must refuse."""
    m = c / (1 - 1e-9)
    while m * (1 - 1e-9) > c:
        m = np.nextafter(m, 0.0)
    while np.nextafter(m, np.inf) * (1 - 1e-9) <= c:
        m = np.nextafter(m, np.inf)
    return float(m), float(np.nextafter(m, np.inf))


@pytest.mark.parametrize("seed", range(3 + len(EDGES)))
def test_the_margin_check_is_clearance_against_the_margin(seed):
    """A candidate is safe by margin exactly when it is within the limits, outside every VO and
    clearance(v) >= margin (1 - 1e-9): at each velocity's own clearance, the largest margin
    that clearance allows accepts it and the next float above refuses it; in crowds and next
    to zones."""
    from vo3d_opt.geometry.membership import clearances, in_vos

    rng = np.random.default_rng(10 + seed)
    kw = _next_to_zone(20 + seed, EDGES[seed - 3]) if seed >= 3 else crowd(20 + seed, n=8)
    options = dict(reciprocal=True, pz_buffer=1.6) if seed == 2 + len(EDGES) else {}
    accepted = refused = 0
    for horizon in (None, 3.0):
        base = prepare(kw["own"], np.asarray(kw["preferred_velocity"]), kw["neighbors"], [],
                       kw["limits"], kw["dt"], Options(horizon=horizon, **options))
        v = np.vstack([_near_surfaces(rng, base.vos.cones, 100), rng.normal(size=(200, 3))])
        free = base.within_limits(v) & ~in_vos(base.vos.cones, base.vos.pyramids, v,
                                               horizon=horizon).any(axis=0)
        c = clearances(base.vos.cones, base.vos.pyramids, v, horizon=horizon)
        for j in np.flatnonzero(free & (c > 1e-9) & (c <= 0.99)):
            for margin, expect in zip(_margins_about(float(c[j])), (True, False)):
                enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"]), kw["neighbors"],
                              [], kw["limits"], kw["dt"],
                              Options(horizon=horizon, margin=margin, **options))
                assert (first_safe(enc, v[j:j + 1]) == 0) == expect, (j, margin, c[j])
                accepted += expect
                refused += not expect
    assert accepted > 5 and refused > 5
