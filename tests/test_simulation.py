"""The decentralised simulator and the metrics, mostly with stand-in selectors and hand-built
records so that the expected figures are known exactly."""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from vo3d_opt.sim.metrics import CONTRACT_KEYS, pair_min_distances, summarize
from vo3d_opt.sim.scenario import Scenario, scenario_from_dict
from vo3d_opt.sim.simulator import RunRecord, Simulator, run_scenario

BASE: dict[str, Any] = {
    "name": "unit-sim",
    "dt": 0.2,
    "max_time": 30.0,
    "goal_tolerance": 0.5,
    "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
    "sensing": {"vehicle_range": 55.0, "obstacle_range": 55.0},
    "defaults": {"r_pz": 10.0, "radius": 0.5, "max_speed": 4.0},
    "agents": [
        {"id": "a", "start": [-20.0, 0.0, 20.0], "goal": [20.0, 0.0, 20.0]},
        {"id": "b", "start": [20.0, 0.0, 20.0], "goal": [-20.0, 0.0, 20.0]},
    ],
}


def scenario(**changes: Any) -> Scenario:
    data = copy.deepcopy(BASE)
    data.update(changes)
    return scenario_from_dict(data)


@dataclass
class Decision:
    velocity: np.ndarray
    status: str = "optimal"
    solve_time: float = 0.0


class Preferred:
    """Stand-in selector: the preferred velocity, and a log of every call."""

    def __init__(self) -> None:
        self.calls: list[dict[str, Any]] = []

    def select(self, *, own, preferred_velocity, neighbors, obstacles, limits, dt):
        self.calls.append(dict(own=own, pref=np.array(preferred_velocity), neighbors=neighbors,
                               obstacles=obstacles, limits=limits, dt=dt))
        return Decision(np.array(preferred_velocity, dtype=float))


class Constant:
    """Stand-in selector: always the same velocity and status."""

    def __init__(self, v, status: str = "optimal") -> None:
        self.v, self.status = np.asarray(v, dtype=float), status

    def select(self, **_: Any):
        return Decision(self.v.copy(), self.status)


# ------------------------------------------------------------------------------ simulator


def test_stand_in_run_reaches_goals_and_stops():
    sc = scenario(agents=[{"id": "a", "start": [0.0, 0.0, 10.0], "goal": [10.0, 0.0, 10.0]}])
    rec = Simulator(sc, Preferred()).run()
    # 10 m at 4 m/s: 0.8 m per step, arrival (0.5 m) after 12 steps, then the run stops.
    assert rec.steps == 12 and rec.arrived[-1].all() and not rec.arrived[-2].any()
    assert np.linalg.norm(rec.positions[-1, 0] - sc.goals[0]) <= 0.5
    np.testing.assert_allclose(np.linalg.norm(rec.velocities[:-1, 0], axis=1), 4.0)
    s = summarize(rec)
    assert s["all_reached"] and s["reached"] == 1 and s["steps"] == 12
    assert s["time"] == pytest.approx(2.4) and s["min_vehicle_distance"] is None
    assert s["min_obstacle_distance"] is None


def test_preferred_velocity_slows_to_land_on_the_goal():
    sc = scenario(goal_tolerance=0.01,
                  agents=[{"id": "a", "start": [0.0, 0.0, 10.0], "goal": [1.0, 0.0, 10.0]}])
    sel = Preferred()
    rec = Simulator(sc, sel).run()
    np.testing.assert_allclose(sel.calls[0]["pref"], [4.0, 0, 0])  # min(4, 1 m / 0.2 s)
    np.testing.assert_allclose(sel.calls[1]["pref"], [1.0, 0, 0])  # min(4, 0.2 m / 0.2 s)
    np.testing.assert_allclose(rec.positions[-1, 0], [1.0, 0.0, 10.0], atol=1e-12)
    assert rec.steps == 2  # 0.8 m, then the last 0.2 m at 1 m/s


def test_same_snapshot_and_what_each_agent_senses():
    sc = scenario(
        sensing={"vehicle_range": 30.0, "obstacle_range": 6.0},
        agents=[
            {"id": "c", "start": [0.0, 0.0, 20.0], "goal": [0.0, 30.0, 20.0], "r_pz": 6.0},
            {"id": "a", "start": [-20.0, 0.0, 20.0], "goal": [20.0, 0.0, 20.0]},
            {"id": "far", "start": [0.0, -35.0, 20.0], "goal": [0.0, -60.0, 20.0], "r_pz": 4.0,
             "max_speed": 2.0},
        ],
        obstacles=[
            {"type": "cylinder", "center": [-20.0, 8.0], "radius": 2.0, "height": 30.0},
            {"type": "box", "center": [-20.0, -7.0], "size": [2.0, 2.0], "height": 30.0},
            {"type": "cylinder", "center": [-24.0, 0.0], "radius": 1.0, "height": 30.0,
             "sensed": False},
        ],
        spheres=[{"center": [0.0, 6.0, 40.0], "radius": 3.0, "margin": 1.0}],
    )
    sel = Preferred()
    Simulator(sc, sel).run(max_steps=1)
    calls = {tuple(c["own"].position): c for c in sel.calls}
    assert [tuple(c["own"].position) for c in sel.calls] == [(-20.0, 0.0, 20.0), (0.0, 0.0, 20.0),
                                                             (0.0, -35.0, 20.0)]  # id order
    a, c, far = calls[(-20.0, 0.0, 20.0)], calls[(0.0, 0.0, 20.0)], calls[(0.0, -35.0, 20.0)]
    # a: c at 20 m (seen, r_pz = max(10, 6)); far at 40.3 m: not seen. Obstacles: the
    # cylinder's surface 6 m away (seen), the box 6 m away (seen), the unsensed one never.
    assert [n.r_pz for n in a["neighbors"]] == [10.0]
    np.testing.assert_allclose(a["neighbors"][0].position, [0.0, 0.0, 20.0])
    assert len(a["obstacles"]) == 2
    # c: sees a (20 m) but not far (35 m > 30 m), nor the sphere (20.9 m from its centre, minus
    # its 3 m radius: 17.9 m > 6 m).
    assert len(c["neighbors"]) == 1 and c["neighbors"][0].r_pz == 10.0
    assert far["neighbors"] == [] and far["limits"].speed == (0.0, 2.0)
    assert all(x["dt"] == 0.2 for x in sel.calls)


def test_neighbours_are_seen_at_the_previous_step():
    sc = scenario()
    sel = Preferred()
    rec = Simulator(sc, sel).run(max_steps=3)
    for k in range(3):
        for i, c in enumerate(sel.calls[2 * k: 2 * k + 2]):
            (nb,) = c["neighbors"]
            other = 1 - i
            np.testing.assert_array_equal(nb.position, rec.positions[k, other])
            expected_v = rec.velocities[k - 1, other] if k else np.zeros(3)
            np.testing.assert_array_equal(nb.velocity, expected_v)


def test_static_spheres_are_zero_velocity_neighbours():
    sc = scenario(spheres=[{"center": [0.0, 0.0, 20.0], "radius": 3.0, "margin": 2.0}])
    sel = Preferred()
    Simulator(sc, sel).run(max_steps=1)
    for c in sel.calls:
        spheres = [n for n in c["neighbors"] if n.r_pz == 5.0]
        assert len(spheres) == 1 and not np.any(spheres[0].velocity)


def test_arrived_agents_hover_and_stop_deciding():
    sc = scenario(agents=[
        {"id": "near", "start": [0.0, 0.0, 20.0], "goal": [2.0, 0.0, 20.0]},
        {"id": "far", "start": [0.0, 30.0, 20.0], "goal": [20.0, 30.0, 20.0]},
    ])
    sel = Preferred()
    rec = Simulator(sc, sel).run()
    k = int(np.argmax(rec.arrived[:, 0]))
    assert 0 < k < rec.steps
    assert np.all(rec.positions[k:, 0] == rec.positions[k, 0])
    assert not rec.decided[k:, 0].any() and rec.decided[:k, 0].all()
    assert np.all(rec.velocities[k:, 0] == 0.0)
    assert rec.decided[:, 1].all() and rec.arrived[-1].all()
    s = summarize(rec)
    assert s["decisions"] == int(rec.decided.sum()) == len(sel.calls)


def test_run_is_deterministic_with_a_stand_in():
    sc = scenario(agents=BASE["agents"] + [{"id": "c", "start": [0.0, 20.0, 10.0],
                                             "goal": [0.0, -20.0, 30.0]}])
    r1, r2 = Simulator(sc, Preferred()).run(), Simulator(sc, Preferred()).run()
    assert r1.same_trajectory(r2)


def test_run_is_deterministic_with_the_real_selector():
    sc = scenario(max_time=6.0, obstacles=[
        {"type": "cylinder", "center": [0.0, 6.0], "radius": 2.0, "height": 30.0}])
    r1 = run_scenario(sc, formulation="plane_qp", progress=False)
    r2 = run_scenario(sc, formulation="plane_qp", progress=False)
    assert r1.steps == r2.steps > 0
    assert r1.same_trajectory(r2)
    assert summarize(r1)["formulation"] == "plane_qp"


def test_first_order_velocity_response():
    sc = scenario(velocity_response_tau=0.8,
                  agents=[{"id": "a", "start": [0.0, 0.0, 10.0], "goal": [100.0, 0.0, 10.0]}])
    rec = Simulator(sc, Constant([4.0, 0.0, 0.0])).run(max_steps=5)
    alpha = 0.2 / 0.8
    expected = 4.0 * (1.0 - (1.0 - alpha) ** np.arange(1, 6))
    np.testing.assert_allclose(rec.velocities[:, 0, 0], expected)
    np.testing.assert_allclose(rec.positions[1:, 0, 0], np.cumsum(expected) * 0.2)
    np.testing.assert_allclose(rec.commands[:, 0, 0], 4.0)
    # tau below dt: a full step, like the ideal kinematics
    fast = Simulator(scenario(velocity_response_tau=0.1, agents=sc.model_dump()["agents"]),
                     Constant([4.0, 0.0, 0.0])).run(max_steps=2)
    np.testing.assert_allclose(fast.velocities[:, 0, 0], 4.0)


def test_non_finite_answers_are_replaced_and_flagged():
    sc = scenario(agents=[{"id": "a", "start": [0.0, 0.0, 10.0], "goal": [10.0, 0.0, 10.0]}])
    rec = Simulator(sc, Constant([np.nan, 0.0, 0.0])).run(max_steps=2)
    assert np.all(rec.velocities == 0.0)
    assert rec.statuses[0, 0].startswith("invalid_velocity")
    assert summarize(rec)["fallbacks"] == 2


# -------------------------------------------------------------------------------- metrics


def hand_record(sc: Scenario, positions, velocities=None, statuses=None, times_s=None) -> RunRecord:
    """A record with the given positions (T+1, N, 3); every agent decided at every step."""
    p = np.asarray(positions, dtype=float)
    t, n = p.shape[0] - 1, p.shape[1]
    v = np.diff(p, axis=0) / sc.dt if velocities is None else np.asarray(velocities, dtype=float)
    st = np.full((t, n), "optimal") if statuses is None else np.asarray(statuses, dtype=str)
    names, codes = np.unique(np.concatenate([[""], st.ravel()]), return_inverse=True)  # "" first
    dtimes = np.full((t, n), 1e-3) if times_s is None else np.asarray(times_s, dtype=float)
    arrived = np.zeros((t + 1, n), dtype=bool)
    arrived[-1] = np.linalg.norm(p[-1] - sc.goals, axis=1) <= sc.goal_tolerance
    return RunRecord(scenario=sc, formulation="hand", solver="none", times=np.arange(t + 1) * sc.dt,
                     positions=p, velocities=v, commands=v.copy(), preferred=v.copy(),
                     decided=np.ones((t, n), dtype=bool), status_codes=codes[1:].reshape(t, n).astype(np.uint16),
                     status_names=tuple(names), decision_times=dtimes,
                     solve_times=dtimes.copy(), arrived=arrived)


def line(a, b, steps: int) -> np.ndarray:
    return np.linspace(np.asarray(a, float), np.asarray(b, float), steps + 1)


def test_contract_keys_and_known_pair_counts():
    # Three agents on a line: a-b goes down to 9 m (inside max(9.5, 10) but no collision),
    # a-c down to 9.8 m (outside max(9.5, 5)), b-c down to 0.8 m (a collision: radii 0.5 + 0.5,
    # and an intrusion). Each pair counts once however long it lasts.
    sc = scenario(agents=[
        {"id": "a", "start": [0.0, 0.0, 20.0], "goal": [0.0, 0.0, 20.0], "r_pz": 9.5},
        {"id": "b", "start": [20.0, 0.0, 20.0], "goal": [9.0, -5.0, 20.0]},
        {"id": "c", "start": [30.0, 0.0, 20.0], "goal": [9.8, 5.0, 20.0], "r_pz": 5.0},
    ])
    a = line([0, 0, 20], [0, 0, 20], 4)
    b = line([20, 0, 20], [9, 0, 20], 4)
    c = np.array([[30, 0, 20], [30, 0, 20], [30, 0, 20], [20, 0, 20], [9.8, 0, 20]], float)
    rec = hand_record(sc, np.stack([a, b, c], axis=1))
    s = summarize(rec)
    assert set(CONTRACT_KEYS) <= set(s)
    assert s["pz_intrusions"] == 2  # a-b (9 m) and b-c (0.8 m)
    assert s["collisions"] == 1  # b-c
    assert s["vehicle_collisions"] == 1 and s["obstacle_collisions"] == 0
    assert s["min_vehicle_distance"] == pytest.approx(0.8)
    assert s["agents"] == 3 and s["steps"] == 4 and s["time"] == pytest.approx(0.8)
    assert s["reached"] == 1 and s["all_reached"] is False  # only a is at its goal


def test_larger_r_pz_of_the_pair_counts():
    sc = scenario(agents=[
        {"id": "a", "start": [0.0, 0.0, 20.0], "goal": [0.0, 0.0, 20.0], "r_pz": 5.0},
        {"id": "b", "start": [8.0, 0.0, 20.0], "goal": [8.0, 0.0, 20.0], "r_pz": 9.0},
    ])
    s = summarize(hand_record(sc, [[[0, 0, 20], [8, 0, 20]]] * 2))
    assert s["pz_intrusions"] == 1 and s["starts_inside_pz"] == 1 and s["collisions"] == 0


def test_pass_between_samples_is_caught():
    # Swapping places within one step: 12 m apart at both samples, through each other between.
    sc = scenario(agents=[
        {"id": "a", "start": [-6.0, 0.0, 20.0], "goal": [6.0, 0.0, 20.0]},
        {"id": "b", "start": [6.0, 0.0, 20.0], "goal": [-6.0, 0.0, 20.0]},
    ], dt=1.0)
    rec = hand_record(sc, [[[-6, 0, 20], [6, 0, 20]], [[6, 0, 20], [-6, 0, 20]]])
    s = summarize(rec)
    assert s["min_vehicle_distance"] == pytest.approx(0.0, abs=1e-12)
    assert s["collisions"] == 1 and s["pz_intrusions"] == 1
    _, _, d = pair_min_distances(rec.positions)
    assert d[0] == pytest.approx(0.0, abs=1e-12)


def test_pair_min_distance_is_exact_on_segments():
    rng = np.random.default_rng(0)
    p = rng.uniform(-10, 10, size=(6, 4, 3))
    ii, jj, d = pair_min_distances(p)
    f = np.linspace(0.0, 1.0, 2001)[:, None, None]
    fine = np.concatenate([p[k] + f * (p[k + 1] - p[k]) for k in range(5)], axis=0)
    brute = np.linalg.norm(fine[:, ii] - fine[:, jj], axis=-1).min(axis=0)
    np.testing.assert_allclose(d, brute, atol=1e-3)
    assert np.all(d <= brute + 1e-12)


def test_obstacle_distance_collisions_and_prism_entries():
    sc = scenario(
        agents=[{"id": "a", "start": [-20.0, 0.0, 10.0], "goal": [20.0, 0.0, 10.0]},
                {"id": "b", "start": [-20.0, 30.0, 10.0], "goal": [20.0, 30.0, 10.0]}],
        obstacles=[{"type": "cylinder", "center": [0.0, 3.3], "radius": 3.0, "height": 30.0},
                   {"type": "box", "center": [0.0, 36.0], "size": [4.0, 4.0], "height": 30.0}],
    )
    # a passes 0.3 m from the cylinder (a collision with radius 0.5); b passes 4 m from the
    # box's face: no collision, but inside its prism (side 4 sqrt 2 + 4 = 9.66 m, half 4.83 m;
    # b's horizontal distance to the box axis is 6 m > 4.83: outside). So only a enters a prism.
    a = line([-20, 0, 10], [20, 0, 10], 40)
    b = line([-20, 30, 10], [20, 30, 10], 40)
    s = summarize(hand_record(sc, np.stack([a, b], axis=1)))
    assert s["min_obstacle_distance"] == pytest.approx(0.3)
    assert s["obstacle_collisions"] == 1 and s["collisions"] == 1
    assert s["obstacle_pz_intrusions"] == 1
    assert s["pz_intrusions"] == 0 and s["min_vehicle_distance"] == pytest.approx(30.0)


def test_unseen_obstacles_count_and_virtual_spheres_do_not():
    sc = scenario(
        agents=[{"id": "a", "start": [-20.0, 0.0, 10.0], "goal": [20.0, 0.0, 10.0]}],
        obstacles=[{"type": "cylinder", "center": [0.0, 4.5], "radius": 3.0, "height": 30.0,
                    "sensed": False}],
        spheres=[{"center": [0.0, 1.0, 10.0], "radius": 0.5, "physical": False},
                 {"center": [0.0, -3.0, 10.0], "radius": 1.0, "margin": 2.5}],
    )
    s = summarize(hand_record(sc, line([-20, 0, 10], [20, 0, 10], 40)[:, None, :]))
    assert s["min_obstacle_distance"] == pytest.approx(1.5)  # the cylinder, not the sphere
    assert s["obstacle_pz_intrusions"] == 2  # the cylinder's prism, the physical sphere's zone


def test_limit_violations_fallbacks_and_times():
    sc = scenario(agents=[{"id": "a", "start": [0.0, 0.0, 39.0], "goal": [0.0, 0.0, 39.5]}],
                  limits={"speed": [0.0, 4.0], "altitude": [0.0, 40.0]})
    z = [39.0, 39.9, 40.0 + 5e-7, 40.5, 41.0, 39.5]  # two samples above the ceiling
    p = np.array([[[0.0, 0.0, zz]] for zz in z])
    v = np.array([[[0, 0, 4.0 + 5e-7]], [[3, 3, 0]], [[0, 0, 1]], [[5, 0, 0]], [[0, 0, -1]]])
    st = [["optimal"], ["infeasible_min_violation"], ["optimal"], ["inside_protected_zone"],
          ["optimal"]]
    times = np.array([[1e-3], [2e-3], [3e-3], [4e-3], [5e-3]])
    s = summarize(hand_record(sc, p, v, st, times))
    assert s["altitude_violations"] == 2
    assert s["speed_violations"] == 2  # 4.24 m/s and 5 m/s; 4 + 5e-7 is within tolerance
    assert s["fallbacks"] == 2
    assert s["status_counts"] == {"inside_protected_zone": 1, "infeasible_min_violation": 1,
                                  "optimal": 3}
    assert s["decision_time_median_us"] == pytest.approx(3000.0)
    assert 4900 < s["decision_time_p99_us"] <= 5000.0
