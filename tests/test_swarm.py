"""VelocitySelector.select_many against a loop of select() calls, built here by
brute force (every pairwise distance, the neighbours in index order), for every option."""
from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt import AgentState, Box, Cylinder, Limits, Neighbor, VelocitySelector

TOL = 1e-9


def random_swarm(seed: int, n: int = 24, side: float = 70.0):
    """n vehicles in a cube of ``side`` m, random velocities, preferred velocities towards
    random goals, protected zones of 3-8 m (some vehicles start inside another's)."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(0.0, side, (n, 3))
    P[:, 2] = rng.uniform(5.0, 45.0, n)
    V = rng.normal(size=(n, 3)) * 1.5
    goals = rng.uniform(0.0, side, (n, 3))
    goals[:, 2] = rng.uniform(5.0, 45.0, n)
    W = (goals - P) / np.linalg.norm(goals - P, axis=1, keepdims=True) * rng.uniform(1.0, 4.0, (n, 1))
    R = rng.uniform(3.0, 8.0, n)
    return P, V, W, R


OBSTACLES = [Cylinder(center=(20.0, 30.0), radius=3.0, height=30.0),
             Box(center=(50.0, 20.0), size=(6.0, 4.0), height=25.0, yaw=0.3),
             Cylinder(center=(40.0, 60.0), radius=2.0, height=60.0)]
SPHERES = np.array([[35.0, 35.0, 25.0, 2.0, 5.0], [10.0, 60.0, 15.0, 1.0, 3.0]])
LIMITS = Limits(speed=(0.0, 4.0), altitude=(0.0, 50.0))


def loop_of_select(sel, P, V, W, R, *, limits, sensing_range, obstacles=(), dt=0.2,
                   max_neighbors=None, decide=None, obstacle_range=None, spheres=None, max_speed=None):
    """What a loop of select() calls gives, each vehicle with the vehicles in range (or its k
    nearest) in index order, then the spheres, as its neighbours."""
    n = P.shape[0]
    decide = np.ones(n, dtype=bool) if decide is None else decide
    dist = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=-1)
    vel, statuses = V.copy(), np.full(n, "", dtype=object)
    for i in np.flatnonzero(decide):
        js = [j for j in range(n) if j != i and dist[i, j] <= sensing_range]
        if max_neighbors is not None:
            js = sorted(sorted(js, key=lambda j: dist[i, j])[:max_neighbors])
        nbrs = [Neighbor(position=P[j], velocity=V[j], r_pz=max(R[i], R[j]), cooperative=bool(decide[j]))
                for j in js]
        for s in [] if spheres is None else spheres:
            gap = max(np.linalg.norm(P[i] - s[:3]) - s[3], 0.0)
            if obstacle_range is None or gap <= obstacle_range:
                nbrs.append(Neighbor(position=s[:3], velocity=(0, 0, 0), r_pz=s[4], cooperative=False))
        obs = [o for o in obstacles if obstacle_range is None or o.surface_distance(P[i]) <= obstacle_range]
        lim = limits
        if max_speed is not None:
            lim = limits.model_copy(update={"speed": (limits.v_min, min(limits.v_max, float(max_speed[i])))})
        d = sel.select(AgentState(position=P[i], velocity=V[i]), W[i], nbrs, obs, lim, dt)
        vel[i], statuses[i] = d.velocity, str(d.status)
    return vel, statuses


def assert_same(sel, seed, n=24, **kw):
    P, V, W, R = random_swarm(seed, n)
    kw = {"sensing_range": 30.0, "limits": LIMITS, **kw}
    many = sel.select_many(P, V, W, R, **kw)
    vel, statuses = loop_of_select(sel, P, V, W, R, **kw)
    np.testing.assert_allclose(many.velocities, vel, rtol=0, atol=TOL)
    assert list(many.statuses) == list(statuses)
    decide = kw.get("decide")
    assert np.array_equal(many.decided, np.ones(n, bool) if decide is None else decide)
    return many


CASES = {
    "default": ({}, {}),
    "reciprocal": (dict(reciprocal=True), {}),
    "pz_buffer": (dict(reciprocal=True, pz_buffer=1.6), {}),
    "horizon": (dict(horizon=4.0), {}),
    "margin": (dict(margin=0.05), {}),
    "acceleration": ({}, dict(limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 50.0), acceleration=3.0))),
    "min_speed": ({}, dict(limits=Limits(speed=(1.0, 4.0), altitude=(0.0, 50.0)))),
    "max_neighbors": (dict(reciprocal=True), dict(max_neighbors=3)),
    "obstacles": ({}, dict(obstacles=OBSTACLES)),
    "obstacle_range": ({}, dict(obstacles=OBSTACLES, spheres=SPHERES, obstacle_range=12.0)),
    "spheres": (dict(reciprocal=True), dict(spheres=SPHERES)),
    "max_speed": ({}, dict(max_speed=np.linspace(2.0, 5.0, 24))),
    "closing_guard": (dict(reciprocal=True, closing_guard=True), {}),
    "no_least_bad_escape": (dict(reciprocal=True, pz_buffer=3.0, least_bad_escape=False), {}),
    "fast": (dict(preset="fast", buffer_steps=0.0), dict(obstacles=OBSTACLES)),
    "everything": (dict(reciprocal=True, pz_buffer=1.0, horizon=8.0, closing_guard=True),
                   dict(obstacles=OBSTACLES, spheres=SPHERES, obstacle_range=20.0, max_neighbors=4,
                        limits=Limits(speed=(0.5, 4.0), altitude=(0.0, 50.0), acceleration=5.0), dt=0.1)),
}


@pytest.mark.parametrize("case", list(CASES))
def test_select_many_equals_a_loop_of_select(case):
    options, kw = CASES[case]
    sel = VelocitySelector(**options)
    statuses = set()
    for seed in range(3):
        many = assert_same(sel, seed, **kw)
        statuses |= set(many.statuses)
        assert many.compiled and many.solve_time > 0
    assert "optimal" in statuses


@pytest.mark.parametrize("options, baseline", [
    pytest.param(dict(preset="paper", reciprocal=True, closing_guard=True),
                 dict(preset="paper", reciprocal=True), id="closing_guard"),
    pytest.param(dict(preset="fast", buffer_steps=0.0),
                 dict(preset="paper", reciprocal=True, closing_guard=True), id="fast"),
])
def test_options_in_a_tight_swarm_change_answers_and_match_select(options, baseline):
    """24 vehicles in a 30 m cube: many pairs within a step of each other's zones, so the
    guard's rows bind, and the fast preset's fewer velocities tried give other answers than the
    defaults'; select_many still equals select."""
    sel = VelocitySelector(**options)
    P, V, W, R = random_swarm(2, side=30.0)
    kw = dict(sensing_range=30.0, limits=LIMITS)
    many = sel.select_many(P, V, W, R, **kw)
    vel, statuses = loop_of_select(sel, P, V, W, R, **kw)
    np.testing.assert_allclose(many.velocities, vel, rtol=0, atol=TOL)
    assert list(many.statuses) == list(statuses)
    other = VelocitySelector(**baseline).select_many(P, V, W, R, **kw)
    assert np.abs(other.velocities - many.velocities).max(axis=1).max() > 0.1


def test_least_bad_escape_in_a_tight_swarm_changes_answers_and_matches_select():
    """24 vehicles in a 30 m cube with the zones widened by 3 m: some vehicles are inside a
    planning sphere with no safe velocity, where the least-bad rule with and without
    ``least_bad_escape`` (the default) differ; select_many equals select for both."""
    P, V, W, R = random_swarm(0, side=30.0)
    kw = dict(sensing_range=30.0, limits=LIMITS)
    answers = []
    for escape in (True, False):
        sel = VelocitySelector(reciprocal=True, pz_buffer=3.0, least_bad_escape=escape)
        many = sel.select_many(P, V, W, R, **kw)
        vel, statuses = loop_of_select(sel, P, V, W, R, **kw)
        np.testing.assert_allclose(many.velocities, vel, rtol=0, atol=TOL)
        assert list(many.statuses) == list(statuses)
        answers.append(many.velocities)
    default = VelocitySelector(reciprocal=True, pz_buffer=3.0).select_many(P, V, W, R, **kw)
    np.testing.assert_array_equal(default.velocities, answers[0])
    assert np.abs(answers[0] - answers[1]).max(axis=1).max() > 0.1


def test_decide_mask_keeps_the_others_and_makes_them_non_cooperative():
    sel = VelocitySelector(reciprocal=True)
    decide = np.arange(24) % 3 != 0
    many = assert_same(sel, 7, decide=decide, obstacles=OBSTACLES)
    P, V, _, _ = random_swarm(7)
    assert np.array_equal(many.velocities[~decide], V[~decide])
    assert set(many.statuses[~decide]) == {""} and "" not in set(many.statuses[decide])
    assert np.all(np.isnan(many.times[~decide])) and np.all(many.times[decide] > 0)
    assert np.all(many.neighbors[~decide] == 0)


def test_neighbour_counts_and_nobody_deciding():
    sel = VelocitySelector()
    P, V, W, R = random_swarm(3)
    many = sel.select_many(P, V, W, R, sensing_range=30.0, max_neighbors=2)
    dist = np.linalg.norm(P[:, None] - P[None], axis=-1)
    in_range = (dist <= 30.0).sum(axis=1) - 1
    assert np.array_equal(many.neighbors, np.minimum(in_range, 2))
    none = sel.select_many(P, V, W, R, decide=np.zeros(24, bool))
    assert np.array_equal(none.velocities, V) and not none.decided.any()
    empty = sel.select_many(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), 5.0)
    assert empty.velocities.shape == (0, 3) and empty.statuses.shape == (0,)


def test_threads_do_not_change_the_answers():
    sel = VelocitySelector(reciprocal=True)
    P, V, W, R = random_swarm(11, n=200, side=160.0)
    one = sel.select_many(P, V, W, R, obstacles=OBSTACLES, threads=1)
    two = sel.select_many(P, V, W, R, obstacles=OBSTACLES, threads=2)
    assert np.array_equal(one.velocities, two.velocities) and np.array_equal(one.statuses, two.statuses)
    assert one.threads == 1 and two.threads == 2


@pytest.mark.parametrize("formulation,solver", [("plane_qp", "clarabel"), ("sampled", None)])
def test_formulations_that_cannot_run_compiled_loop_over_select(formulation, solver):
    sel = VelocitySelector(formulation=formulation, solver=solver, reciprocal=True)
    many = assert_same(sel, 5, n=6, obstacles=OBSTACLES[:1], max_neighbors=3, decide=np.arange(6) != 2)
    assert not many.compiled


P0, V0, W0, R0 = random_swarm(0, n=4)


@pytest.mark.parametrize("change,name", [
    (dict(positions=np.zeros((4, 2))), "positions"),
    (dict(positions=np.zeros(12)), "positions"),
    (dict(velocities=np.zeros((3, 3))), "velocities"),
    (dict(velocities=np.full((4, 3), np.nan)), "velocities"),
    (dict(preferred_velocities=np.full((4, 3), np.inf)), "preferred_velocities"),
    (dict(r_pz=-1.0), "r_pz"),
    (dict(r_pz=np.array([1.0, 2.0, np.nan, 3.0])), "r_pz"),
    (dict(r_pz=np.ones(3)), "r_pz"),
    (dict(decide=np.ones(3, bool)), "decide"),
    (dict(decide=np.array([0.5, 1, 1, 1])), "decide"),
    (dict(obstacles=[object()]), "obstacles"),
    (dict(limits=(0.0, 4.0)), "limits"),
    (dict(dt=0.0), "dt"),
    (dict(sensing_range=-3.0), "sensing_range"),
    (dict(max_neighbors=-1), "max_neighbors"),
    (dict(max_neighbors=2.5), "max_neighbors"),
    (dict(obstacle_range=float("nan")), "obstacle_range"),
    (dict(spheres=np.zeros((2, 4))), "spheres"),
    (dict(max_speed=np.zeros(4)), "max_speed"),
    (dict(threads=0), "threads"),
])
def test_bad_arrays_name_the_argument(change, name):
    kw = dict(positions=P0, velocities=V0, preferred_velocities=W0, r_pz=R0)
    kw.update(change)
    with pytest.raises(ValueError, match=name):
        VelocitySelector().select_many(**kw)


@pytest.mark.parametrize("k", [None, 0, 3, 7, 60])
@pytest.mark.parametrize("spacing", [4.0, 20.0])
def test_neighbour_lists_are_brute_force_with_ties_and_crowds(k, spacing):
    """On a grid (many equal distances: ties go to the lower index) sparse (short lists, sorted
    in place) and dense (every list longer than 48, sorted by numpy)."""
    from vo3d_opt.swarm import vehicle_links

    g = np.arange(5) * spacing
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    who = np.flatnonzero(np.arange(125) % 4 != 1)
    span, idx = vehicle_links(P, who, 30.0, k)
    dist = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=-1)
    longest = 0
    for d, i in enumerate(who):
        js = [j for j in range(125) if j != i and dist[i, j] <= 30.0]
        longest = max(longest, len(js))
        if k is not None:
            js = sorted(sorted(js, key=lambda j: dist[i, j])[:k])
        assert list(idx[span[d, 0]:span[d, 1]]) == js
    assert longest > 48 if spacing == 4.0 else longest < 48


def _brute_lists(P, who, sensing_range, k):
    dist = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=-1)
    out = []
    for i in who:
        js = [j for j in range(P.shape[0]) if j != i and dist[i, j] <= sensing_range]
        out.append(sorted(sorted(js, key=lambda j: dist[i, j])[:k]))
    return out


SWARM_KINDS = ("uniform", "crowd", "sphere", "grid", "coincident", "pile")
TIED = ("grid", "coincident", "pile")  # distances tie: some lists cannot be settled by the query


def _kind_of_swarm(kind, rng):
    n = int(rng.integers(20, 200))
    if kind == "uniform":
        return rng.uniform(-60.0, 60.0, (n, 3))
    if kind == "crowd":
        return rng.normal(0.0, 3.0, (n, 3))
    if kind == "sphere":
        u = rng.normal(size=(n, 3))
        return 40.0 * u / np.linalg.norm(u, axis=1, keepdims=True)
    if kind == "grid":
        g = np.arange(6) * float(rng.choice([1.0, 2.5, 4.0]))
        return np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)[:n]
    if kind == "coincident":  # a few vehicles share each spot
        return np.round(rng.uniform(-3.0, 3.0, (n, 3)))
    return np.round(rng.uniform(-1.0, 1.0, (n, 3)))  # pile: more than k + 5 on a spot


@pytest.mark.parametrize(
    ("crowded", "share", "threads"),
    [(False, 0.05, 1), (True, 0.0, 1), (True, 1.0, 1), (True, 1.0, 3)],
)
@pytest.mark.parametrize("kind", SWARM_KINDS)
def test_nearest_lists_are_brute_force_where_the_tree_cannot_settle_them(
    kind, crowded, share, threads, monkeypatch
):
    """With max_neighbors, in a crowd (``_crowded``, forced here both ways) the lists come from
    one k-nearest query of the k-d tree; a vehicle whose proposals leave a tie possible at the
    edge ranks all within range instead, or, when more than ``_UNSETTLED`` of them would (0: at
    the first, 1: never), the whole call lists every pair within range. Every way the lists
    are the brute-force ones, ranges of 0 and inf included; ties (a grid, shared spots) take
    the slow ways, random positions never do. On 3 threads (each ranking at least 8 vehicles
    here) the lists are the same."""
    from vo3d_opt.swarm import sensing as swarm

    ranked, dropped = [], []
    real_ranked, real_nearest = swarm._ranked_within, swarm._nearest_links
    monkeypatch.setattr(swarm, "_crowded", lambda *args: crowded)
    monkeypatch.setattr(swarm, "_UNSETTLED", share)
    monkeypatch.setattr(swarm, "_ranked_within", lambda *a: ranked.append(1) or real_ranked(*a))
    monkeypatch.setattr(swarm, "_nearest_links", lambda *a: real_nearest(*a) or dropped.append(1))
    monkeypatch.setattr(swarm, "_PART", 8)
    handed = []  # the thread pools asked for: a split takes one of threads - 1 helpers
    real_workers = swarm._workers
    monkeypatch.setattr(swarm, "_workers", lambda n: handed.append(n) or real_workers(n))
    rng = np.random.default_rng(SWARM_KINDS.index(kind))
    for _ in range(20):
        P = _kind_of_swarm(kind, rng)
        who = np.flatnonzero(rng.random(P.shape[0]) < 0.8)
        k, reach = int(rng.integers(1, 12)), float(rng.choice([0.0, 2.0, 10.0, 55.0, np.inf]))
        span, idx = swarm.vehicle_links(P, who, reach, k, threads)
        assert [list(idx[a:b]) for a, b in span] == _brute_lists(P, who, reach, k)
    tied = crowded and kind in TIED
    assert (threads - 1 in handed) == (crowded and threads > 1)
    assert (len(ranked) > 0) == (tied and share == 1.0)
    assert (len(dropped) > 0) == (tied and share == 0.0)


def test_the_nearest_query_serves_only_where_its_distance_is_numpys(monkeypatch):
    """The k-nearest path ranks by a compiled distance that sums the squares as numpy's norm
    does here; a numpy that summed otherwise would turn it off (every pair, numpy's own norm).
    Which path serves depends on the pairs the tree would list per deciding vehicle, the
    vehicles that do not decide counted too."""
    from scipy.spatial import cKDTree

    from vo3d_opt.swarm import sensing as swarm

    if not swarm._NEAREST_OK:
        pytest.skip("this numpy sums a norm's squares otherwise: the k-nearest path is off")
    rng = np.random.default_rng(0)
    sparse = rng.uniform(-2000.0, 2000.0, (50, 3))  # about 0 within range of each other
    assert not swarm._crowded(cKDTree(sparse), sparse, np.arange(50), 55.0, 10)
    # the same 50 deciding beside 250 hovering in a cloud: the tree would list the cloud's pairs
    P = np.concatenate([sparse, rng.normal(0.0, 5.0, (250, 3))])
    tree, everyone = cKDTree(P), np.arange(300)
    assert swarm._crowded(tree, P, everyone[:50], 55.0, 10)
    monkeypatch.setattr(swarm, "_NEAREST_OK", False)
    assert not swarm._crowded(tree, P, everyone, 55.0, 10)
    span, idx = swarm.vehicle_links(P, everyone, 55.0, 10)
    assert [list(idx[a:b]) for a, b in span] == _brute_lists(P, everyone, 55.0, 10)


def test_the_nearest_lists_distance_is_numpys_to_the_last_bit(monkeypatch):
    """A vehicle exactly at the sensing range by numpy's norm is listed: its squares summed the
    other way round, (x0² + (x1² + x2²)), would put it one ulp beyond (66.98560043024172 m)."""
    from vo3d_opt.swarm import sensing as swarm

    x = np.array([66.46, 4.516, -7.053])
    reach = float(np.linalg.norm(x))
    assert np.sqrt(x[0] ** 2 + (x[1] ** 2 + x[2] ** 2)) > reach  # the case this test is for
    P = np.concatenate([np.zeros((1, 3)), x[None], 500.0 + np.arange(60.0)[:, None] * [0, 0, 9]])
    monkeypatch.setattr(swarm, "_crowded", lambda *args: True)
    span, idx = swarm.vehicle_links(P, np.array([0]), reach, 3)
    assert list(idx[span[0, 0] : span[0, 1]]) == [1]


def test_crowded_swarm_equals_a_loop_of_select():
    sel = VelocitySelector(reciprocal=True)
    P, V, W, R = random_swarm(2, n=60, side=30.0)
    for k in (None, 6):
        many = sel.select_many(P, V, W, R, limits=LIMITS, sensing_range=55.0, max_neighbors=k)
        vel, statuses = loop_of_select(sel, P, V, W, R, limits=LIMITS, sensing_range=55.0, max_neighbors=k)
        np.testing.assert_allclose(many.velocities, vel, rtol=0, atol=TOL)
        assert list(many.statuses) == list(statuses)
        assert many.neighbors.max() == (59 if k is None else 6)
