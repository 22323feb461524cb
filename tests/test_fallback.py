"""The least-bad fallback against a plain numpy reference: among its candidates (the tried
answers, the grid on every plane, zero, v_now; with an acceleration limit all of them again
clipped into the reachable box) within the limits, the latest first intrusion, ties nearest
the preferred velocity, the first such candidate in that order."""
from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from encounters import encounters
from vo3d_opt import AgentState, Limits
from vo3d_opt.formulations.common import NEVER, Options, prepare, py_decision_planes
from vo3d_opt.formulations.fallback import py_least_bad, py_polar_grid

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


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
    best = min(np.flatnonzero(ok), key=lambda i: (-t[i], dev[i], i), default=None)
    return None if best is None else (cands[best], t[best], dev[best])


@settings(max_examples=40, **SETTINGS)
@given(kw=encounters(max_neighbors=15), accel=st.one_of(st.none(), st.floats(0.5, 6.0)),
       n_tried=st.integers(0, 12), seed=st.integers(0, 2**16))
def test_least_bad_is_the_latest_intrusion(kw, accel, n_tried, seed):
    rng = np.random.default_rng(seed)
    v_max = kw["limits"].speed[1]
    v_now = rng.uniform(-1, 1, 3) * v_max / 2  # not v_pref: the clipped pass then differs
    limits = Limits(speed=kw["limits"].speed, altitude=kw["limits"].altitude, acceleration=accel)
    own = AgentState(position=kw["own"].position, velocity=v_now)
    enc = prepare(own, np.asarray(kw["preferred_velocity"]), kw["neighbors"], kw["obstacles"],
                  limits, kw["dt"], Options())
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
