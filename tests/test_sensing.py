"""What vehicles sense of each other (vo3d_opt.sim.sensing) and the non-cooperative agents' command
(vo3d_opt.sim.traffic)."""
from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt.sim.sensing import Sensor
from vo3d_opt.sim.traffic import goal_velocity

DT = 0.2


def states(steps: int, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-50, 50, (steps, n, 3)), rng.uniform(-4, 4, (steps, n, 3))


def test_zero_noise_and_latency_return_the_truth_exactly():
    P, V = states(3, 5)
    s = Sensor(5, DT)
    for k in range(3):
        s.push(P[k], V[k])
        for i in range(5):
            p, v = s.sensed(i)
            assert np.array_equal(p, P[k]) and np.array_equal(v, V[k])
        sp, sv = s.sensed_all()
        assert np.array_equal(sp, np.broadcast_to(P[k], (5, 5, 3)))
        assert np.array_equal(sv, np.broadcast_to(V[k], (5, 5, 3)))


@pytest.mark.parametrize("lag", [1, 3])
def test_latency_returns_the_snapshot_exactly_that_old_and_the_own_state_now(lag):
    P, V = states(8, 4)
    s = Sensor(4, DT, latency=lag * DT)
    assert s.lag == lag
    for k in range(8):
        s.push(P[k], V[k])
        old = max(0, k - lag)  # before enough history: the oldest snapshot
        for i in range(4):
            p, v = s.sensed(i)
            others = np.arange(4) != i
            assert np.array_equal(p[others], P[old][others])
            assert np.array_equal(v[others], V[old][others])
            assert np.array_equal(p[i], P[k][i]) and np.array_equal(v[i], V[k][i])


def test_noise_statistics_per_axis():
    n, steps, sp, sv = 40, 60, 0.5, 0.3
    s = Sensor(n, DT, position_noise=sp, velocity_noise=sv, seed=3)
    P, V = states(1, n)
    errs_p, errs_v = [], []
    for _ in range(steps):
        s.push(P[0], V[0])
        p, v = s.sensed_all()
        errs_p.append(p - P[0])
        errs_v.append(v - V[0])
    ep, ev = np.array(errs_p), np.array(errs_v)  # (steps, observer, target, 3)
    own = np.arange(n)
    assert np.all(ep[:, own, own] == 0) and np.all(ev[:, own, own] == 0)  # own state exact
    off = ~np.eye(n, dtype=bool)
    for e, sigma in ((ep[:, off], sp), (ev[:, off], sv)):  # 93,600 draws per axis
        count = e.shape[0] * e.shape[1]
        assert np.all(np.abs(e.mean(axis=(0, 1))) < 5 * sigma / np.sqrt(count))
        np.testing.assert_allclose(e.std(axis=(0, 1)), sigma, rtol=0.02)
    # independent between observers, targets, axes and steps
    flat = ep[:, off].reshape(-1, 3)
    assert np.all(np.abs(np.corrcoef(flat.T) - np.eye(3)) < 0.02)
    assert abs(np.corrcoef(ep[:, 0, 2, 0], ep[:, 1, 2, 0])[0, 1]) < 0.4
    assert abs(np.corrcoef(ep[:-1, 0, 2, 0], ep[1:, 0, 2, 0])[0, 1]) < 0.4


def run_views(seed: int, order: list[int]) -> dict[int, list[np.ndarray]]:
    P, V = states(4, 6)
    s = Sensor(6, DT, position_noise=0.5, velocity_noise=0.2, latency=2 * DT, seed=seed)
    views: dict[int, list[np.ndarray]] = {i: [] for i in order}
    for k in range(4):
        s.push(P[k], V[k])
        for i in order:
            views[i].extend(s.sensed(i))
    return views


def test_seeds_reproduce_whatever_the_order_or_subset_of_observers():
    a = run_views(7, list(range(6)))
    b = run_views(7, [5, 3, 1, 0, 2, 4])
    c = run_views(7, [4])
    for i in range(6):
        assert all(np.array_equal(x, y) for x, y in zip(a[i], b[i]))
    assert all(np.array_equal(x, y) for x, y in zip(a[4], c[4]))
    d = run_views(8, list(range(6)))
    assert not np.array_equal(a[0][0], d[0][0])


@pytest.mark.parametrize(("noise", "latency"), [((0.5, 0.3), 0.4), ((0.0, 0.0), 0.2),
                                                ((0.2, 0.0), 0.0)])
def test_sensed_many_is_sensed_for_each(noise, latency):
    rng = np.random.default_rng(5)
    sensor = Sensor(7, 0.2, position_noise=noise[0], velocity_noise=noise[1], latency=latency,
                    seed=11)
    for _ in range(4):
        sensor.push(rng.normal(size=(7, 3)) * 30.0, rng.normal(size=(7, 3)))
        who = rng.permutation(7)[: rng.integers(1, 8)]
        p, v = sensor.sensed_many(who)
        for d, i in enumerate(who):
            one_p, one_v = sensor.sensed(int(i))
            assert np.array_equal(p[d], one_p) and np.array_equal(v[d], one_v)
    with pytest.raises(ValueError, match="vehicle index"):
        sensor.sensed_many(np.array([0, 7]))


@pytest.mark.parametrize("kwargs, key", [
    (dict(n=0), "n"),
    (dict(n=2.5), "n"),
    (dict(dt=0.0), "dt"),
    (dict(dt=float("nan")), "dt"),
    (dict(position_noise=-0.1), "position_noise"),
    (dict(position_noise=float("inf")), "position_noise"),
    (dict(velocity_noise="0.2"), "velocity_noise"),
    (dict(latency=-0.2), "latency"),
    (dict(latency=0.3), "latency"),
    (dict(seed=-1), "seed"),
    (dict(seed=1.5), "seed"),
])
def test_bad_values_are_rejected_naming_the_field(kwargs, key):
    args = dict(n=3, dt=DT) | kwargs
    with pytest.raises(ValueError, match=f"^{key}:"):
        Sensor(args.pop("n"), args.pop("dt"), **args)


def test_bad_arrays_are_rejected_naming_the_argument():
    s = Sensor(3, DT)
    with pytest.raises(RuntimeError):
        s.sensed(0)
    with pytest.raises(ValueError, match="^positions:"):
        s.push(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="^velocities:"):
        s.push(np.zeros((3, 3)), np.full((3, 3), np.nan))
    s.push(np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="^i:"):
        s.sensed(3)


# ------------------------------------------------------------------------------------ traffic


def test_goal_velocity_flies_straight_at_full_speed_and_lands_on_the_goal():
    rng = np.random.default_rng(2)
    p = rng.uniform(-30, 30, (50, 3))
    goals = p + rng.normal(size=(50, 3)) * rng.choice([0.1, 10.0], size=(50, 1))
    goals[0] = p[0]
    v_max = rng.uniform(1, 4, 50)
    v = goal_velocity(p, goals, v_max, DT)
    speed = np.linalg.norm(v, axis=1)
    to_goal = goals - p
    dist = np.linalg.norm(to_goal, axis=1)
    np.testing.assert_allclose(speed, np.minimum(v_max, dist / DT), rtol=1e-12)
    far = dist > v_max * DT
    # aimed at the goal, and within reach it lands on it in one period
    np.testing.assert_allclose(np.einsum("ij,ij->i", v[far], to_goal[far]),
                               speed[far] * dist[far], rtol=1e-12)
    np.testing.assert_allclose(p[~far] + v[~far] * DT, goals[~far], atol=1e-12)
    assert np.all(v[0] == 0)
    # one max_speed for all
    assert np.array_equal(goal_velocity(p, goals, 2.0, DT), goal_velocity(p, goals, np.full(50, 2.0), DT))


@pytest.mark.parametrize("args, key", [
    ((np.zeros((2, 2)), np.zeros((2, 2)), 1.0, DT), "positions"),
    ((np.zeros((2, 3)), np.zeros((3, 3)), 1.0, DT), "goals"),
    ((np.zeros((2, 3)), np.zeros((2, 3)), [1.0, 2.0, 3.0], DT), "max_speed"),
    ((np.zeros((2, 3)), np.zeros((2, 3)), -1.0, DT), "max_speed"),
    ((np.zeros((2, 3)), np.zeros((2, 3)), 1.0, 0.0), "dt"),
])
def test_goal_velocity_rejects_bad_arrays(args, key):
    with pytest.raises(ValueError, match=f"^{key}:"):
        goal_velocity(*args)
