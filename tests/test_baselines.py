"""The RVO2-3D baseline runner (vo3d_opt.baselines.rvo2): same scenario, same preferred-velocity
rule, same metrics as vo3d_opt's simulator."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vo3d_opt.baselines.rvo2 import (
    default_time_horizon,
    run_rvo2,
    summarize_record,
    summarize_rvo2,
)
from vo3d_opt.generators import fibonacci_sphere, sphere_swap_scenario
from vo3d_opt.sim.metrics import CONTRACT_KEYS
from vo3d_opt.sim.scenario import bundled_dir, scenario_from_dict
from vo3d_opt.sim.traffic import goal_velocity




@pytest.fixture(scope="module")
def swap4():
    sc = sphere_swap_scenario(4)
    rec = run_rvo2(sc)
    return sc, rec, summarize_rvo2(rec)


def test_tiny_swap_summary_has_the_contract_keys_and_plausible_values(swap4):
    sc, rec, s = swap4
    assert set(CONTRACT_KEYS) <= set(s)
    assert s["scenario"] == "sphere-swap-4" and s["formulation"] == "rvo2-3d"
    assert s["solver"].startswith("rvo23d")
    assert s["agents"] == 4
    assert 1 <= s["steps"] <= sc.n_steps
    assert math.isclose(s["time"], s["steps"] * sc.dt)
    assert 0 <= s["reached"] <= 4 and s["all_reached"] == (s["reached"] == 4)
    r_pz = float(sc.r_pz[0])
    # RVO2 radius r_pz / 2 per agent: a pair keeps (about) r_pz apart; float32 rounding only
    assert s["min_vehicle_distance"] >= 0.99 * r_pz
    assert s["min_obstacle_distance"] is None
    assert s["collisions"] == 0
    assert s["altitude_violations"] == 0 and s["speed_violations"] == 0
    assert s["fallbacks"] is None  # RVO2 does not report infeasibility
    assert 0 < s["decision_time_median_us"] <= s["decision_time_p99_us"]
    assert s["compute_time_per_agent_step_us"] > 0
    assert s["decisions"] == int(rec.decided.sum()) == s["status_counts"]["rvo2"]


def test_record_shapes_and_the_shared_preferred_velocity_rule(swap4):
    sc, rec, _ = swap4
    T, n = rec.steps, sc.n_agents
    assert rec.positions.shape == (T + 1, n, 3) and rec.velocities.shape == (T, n, 3)
    assert rec.arrived.shape == (T + 1, n) and rec.decided.shape == (T, n)
    assert np.allclose(rec.positions[0], sc.starts, atol=1e-4)  # RVO2-3D stores float32
    expected = goal_velocity(sc.starts, sc.goals, sc.max_speed, sc.dt)
    assert np.allclose(rec.preferred[0], expected)
    # the positions follow p += v dt with the recorded velocities
    assert np.allclose(np.diff(rec.positions, axis=0), rec.velocities * sc.dt, atol=1e-3)
    speeds = np.linalg.norm(rec.velocities, axis=-1)
    assert speeds.max() <= sc.max_speed.max() * (1 + 1e-6)
    assert rec.extra["time_horizon"] == pytest.approx(default_time_horizon(sc))
    assert rec.extra["radius"] == pytest.approx(sc.r_pz[0] / 2)
    assert np.all(rec.extra["step_times"] > 0)


def _head_on(offset: float = 0.5):
    return scenario_from_dict({
        "name": "head-on", "dt": 0.2, "max_time": 60.0,
        "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
        "agents": [{"id": "a", "start": [-40.0, 0.0, 20.0], "goal": [40.0, 0.0, 20.0]},
                   {"id": "b", "start": [40.0, offset, 20.0], "goal": [-40.0, offset, 20.0]}],
    })


def test_head_on_pair_arrives_and_keeps_the_protected_distance():
    sc = _head_on()
    rec = run_rvo2(sc)
    s = summarize_rvo2(rec)
    assert s["all_reached"] and s["reached"] == 2
    straight = 80.0 - sc.goal_tolerance
    assert s["arrival_time_max"] >= straight / 4.0 - 1e-9
    assert s["min_vehicle_distance"] >= 0.99 * 10.0
    # arrived agents hover: no motion after their arrival
    arrived_at = np.argmax(rec.arrived, axis=0)
    for i, k in enumerate(arrived_at):
        assert np.allclose(rec.velocities[k:, i], 0.0)


def test_step_cap_and_parameters():
    sc = _head_on()
    rec = run_rvo2(sc, max_steps=7, time_horizon=3.0, max_neighbors=1)
    assert rec.steps == 7 and rec.extra["time_horizon"] == 3.0 and rec.extra["max_neighbors"] == 1
    s = summarize_record(rec)
    assert s["steps_capped"] is True and s["reached"] == 0
    with pytest.raises(ValueError, match="time_horizon"):
        run_rvo2(sc, time_horizon=0.0)


def test_scenarios_with_obstacles_are_refused():
    with pytest.raises(ValueError, match="agent-only"):
        run_rvo2(bundled_dir() / "paper-case2-two-uav-six-obstacles.yaml")


def test_bundled_agent_only_scenario_runs():
    rec = run_rvo2(bundled_dir() / "vertical-encounter.yaml")
    s = summarize_rvo2(rec)
    assert s["agents"] == 3 and s["all_reached"] and s["collisions"] == 0


@pytest.mark.parametrize("n", [2, 4, 10, 100])
def test_sphere_swap_scenario_geometry(n):
    sc = sphere_swap_scenario(n)
    r_pz = float(sc.r_pz[0])
    starts, goals = sc.starts, sc.goals
    centre = (starts + goals) / 2
    assert np.allclose(centre, centre[0])  # every goal is the start's antipode
    radius = np.linalg.norm(starts - centre, axis=1)
    assert np.allclose(radius, radius[0])
    d = np.linalg.norm(starts[:, None] - starts[None], axis=-1)
    d[np.arange(n), np.arange(n)] = np.inf
    assert d.min() >= r_pz * 1.5  # nobody starts inside (or near) a protected zone
    assert sc.start_warnings() == []
    z_lo, z_hi = sc.limits.altitude
    assert starts[:, 2].min() > z_lo and starts[:, 2].max() < z_hi
    # three straight flights' time + 30 s: the whole N = 10,000 swap's last agents, held in the
    # centre's jam for minutes, were still flying home after twice that (docs/results/swarm.md)
    straight = 2.0 * radius[0] / float(sc.max_speed[0])
    assert 3.0 * straight + 30.0 <= sc.max_time < 3.0 * straight + 31.0


def test_fibonacci_sphere_is_on_the_unit_sphere():
    p = fibonacci_sphere(50)
    assert p.shape == (50, 3) and np.allclose(np.linalg.norm(p, axis=1), 1.0)

