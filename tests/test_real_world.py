"""The real-world keys in the scenario and the loop (dynamics, wind,
noisy and late sensing, agents that do not avoid), the margins the simulator derives from them
(vo3d_opt.sim.safety) and the safety they buy, on small cases."""
from __future__ import annotations

import copy
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from encounters import PAPER_GRID
from vo3d_opt.geometry import build_pyramids
from vo3d_opt.sim.dynamics import make_dynamics
from vo3d_opt.sim.deciders import PerAgentSelect, decision_step
from vo3d_opt.sim.metrics import CONTRACT_KEYS, summarize
from vo3d_opt.sim.safety import (
    ALTITUDE_CLEARANCE,
    NOISE_QUANTILE,
    derive_margins,
    inflated,
    planning_bodies,
    planning_limits,
    prism_clearance,
    response_time,
    within_reach,
)
from vo3d_opt.sim.scenario import (
    ScenarioError,
    load_scenario,
    scenario_from_dict,
    scenario_variant,
)
from vo3d_opt.sim.simulator import fly, run_scenario, scenario_selector
from vo3d_opt.sim.traffic import goal_velocity
from vo3d_opt.types import Box, Cylinder

# Two UAVs head-on 40 m apart and a third crossing: small enough for RotorPy in a few seconds.
SMALL: dict[str, Any] = {
    "name": "unit-real",
    "dt": 0.2,
    "max_time": 14.0,
    "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 20.0]},
    "defaults": {"r_pz": 5.0, "radius": 0.5, "max_speed": 4.0},
    "agents": [
        {"id": "a", "start": [-20.0, 0.0, 10.0], "goal": [20.0, 0.0, 10.0]},
        {"id": "b", "start": [20.0, 0.5, 10.0], "goal": [-20.0, 0.5, 10.0]},
    ],
}


def small(**keys: Any) -> Any:
    data = copy.deepcopy(SMALL)
    data.update(keys)
    return scenario_from_dict(data, "small.yaml")


# ---------------------------------------------------------------------------- the keys


def _with(path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    data = copy.deepcopy(SMALL)
    node = data
    for key in path[:-1]:
        node = node.setdefault(key, {}) if isinstance(key, str) else node[key]
    node[path[-1]] = value
    return data


BAD = [
    (("dynamics",), {"model": "jet"}, "dynamics.model"),
    (("dynamics",), {"model": "first_order"}, "dynamics.tau"),
    (("dynamics",), {"model": "first_order", "tau": -1.0}, "dynamics.tau"),
    (("dynamics",), {"model": "rotorpy", "vehicle": "blimp"}, "dynamics.vehicle"),
    (("dynamics",), {"model": "kinematic", "tau": 0.5}, "dynamics.tau"),
    (("dynamics",), {"model": "rotorpy", "substep_rate": 0}, "dynamics.substep_rate"),
    (("dynamics",), {"model": "rotorpy", "speed": 3}, "dynamics.speed"),
    (("dynamics",), {"model": "rotorpy", "batched": "yes"}, "dynamics.batched"),
    (("dynamics",), {"model": "first_order", "tau": 0.5, "batched": True}, "dynamics.batched"),
    (("wind",), {"type": "constant", "velocity": [3.0, 0.0, 0.0]}, "wind"),
    (("wind",), {"type": "gusty", "velocity": [3.0, 0.0, 0.0]}, "wind.type"),
    (("sensing", "position_noise"), -0.1, "sensing.position_noise"),
    (("sensing", "velocity_noise"), "0.3", "sensing.velocity_noise"),
    (("sensing", "latency"), 0.3, "sensing.latency"),
    (("sensing", "seed"), 1.5, "sensing.seed"),
    (("agents", 0, "avoids"), "no", "agents[0].avoids"),
    (("safety", "pz_buffer"), -1.0, "safety.pz_buffer"),
    (("safety", "altitude_margins"), 1.0, "safety.altitude_margins"),
    (("safety", "speed_margin"), 4.0, "safety.speed_margin"),  # no speed left to plan with
    (("velocity_response_tau",), 0.5, "velocity_response_tau"),  # with dynamics below
]


@pytest.mark.parametrize(("path", "value", "key"), BAD, ids=[b[2] for b in BAD])
def test_a_bad_value_of_a_real_world_key_is_rejected_at_its_key(tmp_path: Path, path, value, key):
    data = _with(path, value)
    if key == "wind.type":
        data["dynamics"] = {"model": "rotorpy"}
    if key == "velocity_response_tau":
        data["dynamics"] = {"model": "first_order", "tau": 0.5}
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(ScenarioError) as err:
        load_scenario(f)
    msg = str(err.value)
    assert msg.startswith(f"{f}: {key}: ") and "\n" not in msg, msg


def test_velocity_response_tau_is_first_order_under_another_name():
    alias = run_scenario(small(velocity_response_tau=0.5), progress=False)
    named = run_scenario(small(dynamics={"model": "first_order", "tau": 0.5}), progress=False)
    assert alias.same_trajectory(named)
    assert alias.extra["margins"] == named.extra["margins"]


# ---------------------------------------------------------------------------- the margins


def test_the_margins_are_derived_as_documented():
    sc = small(dynamics={"model": "first_order", "tau": 1.0},
               sensing={"position_noise": 0.5, "velocity_noise": 0.3, "latency": 0.4, "seed": 3})
    m, dt, v = derive_margins(sc), 0.2, 4.0
    assert m.tau_eff == 1.0 and m.acceleration == pytest.approx(v / 1.0)
    assert m.tracking == pytest.approx(min(2 * v, math.sqrt(3) * m.acceleration * dt) * 1.0)
    noise = NOISE_QUANTILE * (0.5 + 0.3 * (dt + 0.4))
    assert m.pz_buffer == pytest.approx(2 * v * dt + 2 * m.tracking + noise + v * 0.4)
    assert m.obstacle_margin == pytest.approx(m.tracking + 0.5)
    assert m.prism_rise == pytest.approx(m.tracking)
    assert m.altitude_margin == pytest.approx(max(v * 1.0, m.tracking))
    lim = planning_limits(sc.limits, m)
    assert lim.altitude == pytest.approx((m.altitude_margin, 20.0 - m.altitude_margin))
    assert lim.acceleration == pytest.approx(m.acceleration)
    # ideal kinematics: nothing beyond the discretisation buffer of the kinematic simulator
    k = derive_margins(small())
    assert (k.acceleration, k.tracking, k.altitude_margin, k.prism_rise) == (None, 0.0, 0.0, 0.0)
    assert k.pz_buffer == pytest.approx(2 * v * dt)


def test_the_margins_can_be_overridden_and_the_altitude_margin_keeps_starts_plannable():
    sc = small(dynamics={"model": "first_order", "tau": 1.0},
               safety={"pz_buffer": 0.7, "acceleration": 0.0, "altitude_margin": 0.25})
    m = derive_margins(sc)
    assert (m.pz_buffer, m.acceleration, m.altitude_margin) == (0.7, None, 0.25)
    assert m.tracking == pytest.approx(2 * 4.0 * 1.0)  # no bound: a full reversal's lag
    over = small(dynamics={"model": "first_order", "tau": 1.0},
                 selector_options={"pz_buffer": 0.3}, limits={"speed": [0, 4], "altitude": [0, 20],
                                                             "acceleration": 2.5})
    mo = derive_margins(over)
    assert (mo.pz_buffer, mo.acceleration) == (0.3, 2.5)
    sel, _, _ = scenario_selector(over)
    assert sel.config.vo.pz_buffer == 0.3
    # a start 1 m above the floor caps the altitude margin below 1 m
    low = copy.deepcopy(SMALL)
    low["agents"][0]["start"] = [-20.0, 0.0, 1.0]
    low["dynamics"] = {"model": "first_order", "tau": 1.0}
    m_low = derive_margins(scenario_from_dict(low))
    assert 0.99 <= m_low.altitude_margin < 1.0


def reversal_lag(ramp: bool) -> tuple[float, float]:
    """(measured, derived) response time of a hummingbird reversing from 4 to -4 m/s with
    commands rate-limited as the simulator does. Measured: how far it ends up behind the path
    its commands plan (scaled by its steady speed ratio: drag leaves a steady gap), over the
    velocity change. A lag tau behind every change puts it dv tau behind."""
    sc = small(dynamics={"model": "rotorpy", "vehicle": "hummingbird", "command_ramp": ramp})
    rate = derive_margins(sc).command_rate
    dyn = make_dynamics(sc.vehicle_dynamics)
    dyn.reset(np.array([[0.0, 0.0, 20.0]]), np.array([[4.0, 0.0, 0.0]]))
    u = np.array([[4.0, 0.0, 0.0]])
    for _ in range(15):
        dyn.step(u, 0.2)
    ratio, planned = dyn.velocities[0, 0] / 4.0, dyn.positions[0, 0]
    for _ in range(50):
        u = within_reach(np.array([[-4.0, 0.0, 0.0]]), u, rate, 0.2, np.array([4.0]))
        dyn.step(u, 0.2)
        planned += ratio * u[0, 0] * 0.2
    measured = (dyn.positions[0, 0] - planned) / (8.0 * ratio)
    return measured, response_time(sc.vehicle_dynamics, 0.2)


def test_rotorpy_response_time_bounds_the_lag_and_the_ramp_adds_half_a_period():
    # the margins are derived from tau_eff: it must not understate the lag
    ramped, stepped = reversal_lag(True), reversal_lag(False)
    for measured, derived in (ramped, stepped):
        assert measured <= derived
    # the ramped set-point reaches each command dt / 2 later on average
    assert ramped[0] - stepped[0] == pytest.approx(0.1, rel=0.1)
    assert ramped[1] - stepped[1] == pytest.approx(0.1)


@pytest.mark.parametrize("body", [
    Cylinder(center=(0.0, 0.0), radius=2.0, height=10.0),
    Box(center=(1.0, 2.0), size=(4.0, 2.0), height=8.0, yaw=0.4),
    Box(center=(1.0, 2.0), size=(4.0, 2.0), height=8.0, L_pz=6.0, h_pz=9.0),
])
def test_an_obstacle_prism_is_widened_only_beyond_its_own_margin(body):
    own = prism_clearance(body)
    assert inflated(body, own - 0.1) is body
    wide = inflated(body, own + 1.5)
    assert prism_clearance(wide) == pytest.approx(own + 1.5)
    # outside the widened prism, a point is at least that far from the surface
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-20, 20, (4000, 2)), rng.uniform(0, 15, 4000)])
    outside = (np.linalg.norm(pts[:, :2] - wide.center, axis=1) >= wide.side / 2) | (
        pts[:, 2] >= wide.prism_height)
    assert np.all(body.surface_distance(pts[outside]) >= own + 1.5 - 1e-9)
    # a rise beyond the widening raises the top only
    top = inflated(body, own + 0.5, rise=1.2)
    assert top.side == pytest.approx(inflated(body, own + 0.5).side)
    assert top.prism_height == pytest.approx(body.prism_height + 1.2)
    assert inflated(body, own + 0.5, rise=0.1) == inflated(body, own + 0.5)


def test_prism_tops_are_raised_by_the_tracking_error_but_not_over_a_goal():
    """A lagging vehicle strays up to ``tracking`` below a ray grazing a prism's flat top
    (sweep `lagged` encounter 1893, tests/test_sweep.py): the selector plans with every top
    raised by it, but never over a start or goal above the prism (it would be unreachable)."""
    low = {"type": "cylinder", "center": [0.0, 0.0], "radius": 1.0, "height": 6.0}
    far = {"type": "box", "center": [0.0, 30.0], "size": [2.0, 2.0], "height": 6.0}
    lagged = {"dynamics": {"model": "first_order", "tau": 1.0}, "obstacles": [low, far]}
    sc = small(**lagged)
    m = derive_margins(sc)
    plan = planning_bodies(sc, m)
    assert [b.prism_height for b in plan] == pytest.approx([8.0 + m.tracking] * 2)
    assert [b.side for b in plan] == pytest.approx([b.side for b in sc.bodies])
    goal_above = copy.deepcopy(SMALL["agents"])
    goal_above[0]["goal"] = [0.5, 0.0, 8.3]  # 0.3 m above the cylinder's prism
    plan = planning_bodies(small(**lagged, agents=goal_above), m)
    assert plan[0].prism_height == pytest.approx(8.3 - ALTITUDE_CLEARANCE)
    assert plan[1].prism_height == pytest.approx(8.0 + m.tracking)
    given = small(**lagged, safety={"obstacle_margin": 2.5})
    assert derive_margins(given).prism_rise == 0.0


def test_a_top_raised_to_within_the_tracking_error_of_the_ceiling_goes_up_to_it():
    """Over a raised top just under the planning ceiling a lagging vehicle cannot keep above
    the one and below the other (sweep `lagged` 76920 entered such a prism): the top goes up to
    the ceiling, which the selector plans round; a top with room to spare, or under a goal,
    stays where it was."""
    lagged = {"dynamics": {"model": "first_order", "tau": 1.0}}
    m = derive_margins(small(**lagged))
    ceiling = SMALL["limits"]["altitude"][1] - m.altitude_margin
    assert m.tracking > 0.2

    def cylinder(y: float, gap: float) -> dict:  # its raised top gap below the ceiling
        height = ceiling - gap - m.tracking - 2.0  # the prism's own 2 m above the body
        return {"type": "cylinder", "center": [0.0, y], "radius": 1.0, "height": height}

    thin, roomy = cylinder(-30.0, 0.5 * m.tracking), cylinder(30.0, 2.0 * m.tracking)
    sc = small(**lagged, obstacles=[thin, roomy])
    assert derive_margins(sc) == m
    plan = planning_bodies(sc, m)
    assert plan[0].prism_height == pytest.approx(ceiling + ALTITUDE_CLEARANCE)
    assert plan[1].prism_height == pytest.approx(ceiling - 2.0 * m.tracking)
    goal_above = copy.deepcopy(SMALL["agents"])
    goal_above[0]["goal"] = [0.5, -30.0, ceiling - 0.1 * m.tracking]
    plan = planning_bodies(small(**lagged, obstacles=[thin, roomy], agents=goal_above), m)
    assert plan[0].prism_height == pytest.approx(ceiling - 0.5 * m.tracking)
    sized = small(**lagged, obstacles=[thin], safety={"obstacle_margin": 2.0 + m.tracking})
    given = derive_margins(sized)  # the scenario sizes its obstacles alone: no rise
    assert given.prism_rise == 0.0 and given.tracking == m.tracking
    assert planning_bodies(sized, given)[0].prism_height == pytest.approx(ceiling - 0.5 * m.tracking)


@pytest.mark.parametrize("family", ["group", "lagged", "intruder", "noisy", "rotorpy", "files"])
def test_a_planning_prisms_roof_edge_band_lies_inside_the_scenarios_own_prism(family):
    """Over an obstacle's roof inside its prism a vehicle is under the top even where the
    prism's side is nearer than its top (algorithm/vo.hpp, ``under_top``): a band at the roof's
    edge, within the rim, up to h_pz - (L_pz/2 - rim) (where the side gap L_pz/2 - dist is
    least). For every prism the simulator plans with below its ceiling that band lies inside
    the scenario's own prism by more than the metrics' tolerance: a vehicle there counts as an
    intrusion, so the roof rule changes no decision of a run without one. A top raised by more
    than the prism is widened plus its side margin would break it; points of the band that the
    compiled core flags are checked against the metrics' own test too."""
    from vo3d_opt.sim.metrics import TOL
    from vo3d_opt.sim.scenario.geometry import prism_contains
    from vo3d_opt.sweep import make_encounter

    if family == "files":  # the bundled ones with obstacles, as the real-world table flies them
        here = Path(__file__).parents[1]
        files = [load_scenario(f) for f in sorted(here.glob("scenarios/*.y*ml"))]
        lags = [{}, {"dynamics": {"model": "first_order", "tau": 1.0}},
                {"dynamics": {"model": "rotorpy"}}]
        scenarios = [scenario_variant(sc, **keys) if keys else sc
                     for sc in files if sc.bodies for keys in lags]
    else:
        scenarios = [make_encounter(family, 0, i).load() for i in range(60)]
    rng, prisms, band = np.random.default_rng(2), 0, 0
    for sc in scenarios:
        m = derive_margins(sc)
        ceiling = planning_limits(sc.limits, m).altitude[1]
        for own, plan in zip(sc.bodies, planning_bodies(sc, m), strict=True):
            if plan.prism_height >= ceiling:
                continue  # planned as reaching far above: no roof to be over
            rim = plan.prism[5]
            band_top = plan.prism_height - (plan.side / 2 - rim)
            assert band_top < own.prism_height - TOL and rim < own.side / 2 - TOL, sc.name
            prisms += 1
            dist = rim * np.sqrt(rng.uniform(0.9, 1.0, 20))  # near the rim, where it is tallest
            z = rng.uniform(plan.height, plan.prism_height, 20)
            points = np.column_stack([plan.center[0] + dist, np.full(20, plan.center[1]), z])
            for q in points:
                pyr = build_pyramids(q, np.array([plan.prism]))
                if pyr.over_roof[0] and not pyr.hi[0, 2] < -pyr.lo[0, 0]:
                    outward = q + (TOL, 0.0, TOL)  # the metrics' shrink: a little out and up
                    assert prism_contains(own, outward), (sc.name, q)
                    band += 1
    # without a tracking error the planned prism is the scenario's, its margins equal: no band
    assert prisms > 0 and (band > 0) == (family in ("lagged", "rotorpy", "files"))


# ---------------------------------------------------------------------------- traffic


def test_an_agent_that_does_not_avoid_flies_straight_and_the_others_take_the_avoidance():
    data = copy.deepcopy(SMALL)
    data["agents"][1]["avoids"] = False
    sc = scenario_from_dict(data)
    rec = run_scenario(sc, progress=False)
    b = 1
    flying = ~rec.arrived[:-1, b]
    straight = np.array([goal_velocity(rec.positions[k], sc.goals, sc.max_speed, sc.dt)[b]
                         for k in range(rec.steps)])
    np.testing.assert_allclose(rec.velocities[flying, b], straight[flying], atol=1e-12)
    assert not rec.decided[:, b].any() and rec.decided[0, 0]
    assert np.allclose(rec.positions[:, b, 1:], rec.positions[0, b, 1:], rtol=0, atol=1e-9)
    s = summarize(rec)
    assert s["collisions"] == 0 and s["pz_intrusions"] == 0 and s["all_reached"]
    # the avoider took all of the avoidance: more than it does when both avoid
    both = summarize(run_scenario(small(), progress=False))
    assert s["path_length_ratio"] > both["path_length_ratio"]


@pytest.mark.parametrize("dynamics", ["kinematic", "first_order"])
def test_an_arrived_agent_steps_out_of_an_intruders_way_and_comes_home(dynamics):
    """``a`` hovers at its goal from the start; ``b`` does not avoid and flies straight through
    it. ``a`` decides again while ``b`` is in range, keeps both zones apart and is home at the
    end (hovering without deciding, it would be hit)."""
    data = copy.deepcopy(SMALL)
    data["agents"][0].update(start=[0.0, 0.0, 10.0], goal=[0.0, 0.0, 10.0])
    data["agents"][1].update(avoids=False, start=[30.0, 0.5, 10.0], goal=[-30.0, 0.5, 10.0])
    data["max_time"] = 25.0
    if dynamics == "first_order":
        data["dynamics"] = {"model": "first_order", "tau": 0.5}
    sc = scenario_from_dict(data, "watch.yaml")
    rec = run_scenario(sc, progress=False)
    assert rec.arrived[0, 0] and rec.decided[:, 0].any() and not rec.decided[:, 1].any()
    assert np.linalg.norm(rec.positions[:, 0] - [0.0, 0.0, 10.0], axis=1).max() > 1.0  # it moved
    s = summarize(rec)
    assert s["collisions"] == 0 and s["pz_intrusions"] == 0 and s["all_reached"]
    assert np.linalg.norm(rec.positions[-1, 0] - sc.goals[0]) <= sc.goal_tolerance
    assert rec.steps < sc.n_steps  # the run ended with everyone home, before max_time


def test_a_watcher_that_cannot_get_home_is_not_counted_arrived():
    """The intruder stops 3 m from ``a``'s goal, inside its zone: ``a`` stays away to the end,
    and the run does not count it as arrived."""
    data = copy.deepcopy(SMALL)
    data["agents"][0].update(start=[0.0, 0.0, 10.0], goal=[0.0, 0.0, 10.0])
    data["agents"][1].update(avoids=False, start=[30.0, 0.5, 10.0], goal=[-3.0, 0.5, 10.0])
    sc = scenario_from_dict(data, "blocked.yaml")
    rec = run_scenario(sc, progress=False)
    assert rec.steps == sc.n_steps and rec.arrived[0, 0] and not rec.arrived[-1, 0]
    s = summarize(rec)
    assert s["collisions"] == 0 and not s["all_reached"]


def test_the_bundled_intruder_does_not_avoid_and_nobody_collides():
    sc = load_scenario("intruder-crossing-four")
    assert list(sc.avoids) == [True, True, True, True, False]
    assert np.max(sc.max_speed[~sc.avoids]) <= np.min(sc.max_speed[sc.avoids])
    s = summarize(run_scenario(sc, progress=False))
    assert s["collisions"] == 0 and s["all_reached"]


# ---------------------------------------------------------------------------- sensing


class Recorder:
    """A SelectorLike that flies the preferred velocity and records what it was shown."""

    def __init__(self) -> None:
        self.seen: list[tuple[str, np.ndarray, np.ndarray]] = []

    def select(self, *, own, preferred_velocity, neighbors, obstacles, limits, dt):
        self.seen.append((own.position.copy(), np.array([n.position for n in neighbors])))

        class D:
            velocity, status, solve_time = np.asarray(preferred_velocity, float), "optimal", 0.0
        return D()


def test_latency_delays_what_is_sensed_by_exactly_k_steps_and_the_own_state_is_exact():
    sc = small(sensing={"latency": 0.6})  # 3 steps
    rec_sel = Recorder()
    step = decision_step(sc, rec_sel)
    assert isinstance(step, PerAgentSelect) and step.sensor is not None
    rec = fly(sc, step, progress=False, max_steps=10)
    own = np.array([s[0] for s in rec_sel.seen]).reshape(10, 2, 3)
    other = np.array([s[1][0] for s in rec_sel.seen]).reshape(10, 2, 3)
    np.testing.assert_array_equal(own, rec.positions[:10])
    for k in range(10):
        lag = max(k - 3, 0)
        np.testing.assert_array_equal(other[k, 0], rec.positions[lag, 1])
        np.testing.assert_array_equal(other[k, 1], rec.positions[lag, 0])


def test_sensing_noise_is_reproducible_for_a_seed_and_changes_with_it():
    noisy = {"position_noise": 0.5, "velocity_noise": 0.3, "latency": 0.2}
    one = run_scenario(small(sensing={**noisy, "seed": 1}), progress=False, max_steps=30)
    again = run_scenario(small(sensing={**noisy, "seed": 1}), progress=False, max_steps=30)
    other = run_scenario(small(sensing={**noisy, "seed": 2}), progress=False, max_steps=30)
    assert one.same_trajectory(again)
    assert not np.array_equal(one.positions, other.positions)


def test_paper_case1_under_noise_and_latency_is_collision_free():
    sc = scenario_variant(load_scenario("paper-case1-ten-uav-crossing"),
                          sensing={"position_noise": 0.5, "velocity_noise": 0.3,
                                   "latency": 0.2, "seed": 1})
    s = summarize(run_scenario(sc, progress=False))
    assert s["collisions"] == 0 and s["all_reached"]


# ---------------------------------------------------------------------------- dynamics


def test_the_derived_margins_keep_a_lagging_swarm_off_the_altitude_limits_and_the_boxes():
    # encounter 734 of the lagged sweep (first-order lag, boxes), on the paper's planes and
    # grid: planning to the real altitude limits (margin off) dips below the floor; the derived
    # margin keeps every sample inside.
    shipped = load_scenario(Path(__file__).parent / "data" / "sweep-failures" /
                            "lagged-s0-i734.yaml")
    base = scenario_variant(shipped, selector_options={**shipped.selector_options, **PAPER_GRID})
    assert base.vehicle_dynamics.model == "first_order"
    off = summarize(run_scenario(scenario_variant(base, safety={"altitude_margin": 0.0}),
                                 progress=False))
    assert off["altitude_violations"] > 0
    for sc in (base, shipped):  # on those planes and on the preset's own
        on = summarize(run_scenario(sc, progress=False))
        assert on["altitude_violations"] == 0 and on["collisions"] == 0 and on["all_reached"]
        assert on["pz_intrusions"] == 0 and on["obstacle_pz_intrusions"] == 0


def test_rotorpy_in_a_wind_in_the_loop_judged_on_its_sub_steps():
    # two hummingbirds head-on 24 m apart in a 3 m/s cross wind, 50 sub-steps a second
    data = copy.deepcopy(SMALL)
    data["defaults"]["r_pz"] = 3.0
    data["agents"][0]["start"], data["agents"][1]["start"] = [-12.0, 0.0, 10.0], [12.0, 0.5, 10.0]
    data["agents"][0]["goal"], data["agents"][1]["goal"] = [12.0, 0.0, 10.0], [-12.0, 0.5, 10.0]
    sc = scenario_from_dict({**data, "max_time": 30.0,  # arrives at 9.2 s here
                             "dynamics": {"model": "rotorpy", "vehicle": "hummingbird",
                                          "substep_rate": 50.0},
                             "wind": {"type": "constant", "velocity": [0.0, 3.0, 0.0]}})
    rec = run_scenario(sc, progress=False)
    s = summarize(rec)
    assert set(CONTRACT_KEYS) <= set(s)
    per = 10  # 0.2 s at 50 Hz (the lowest stable rate, formulations/dynamics.md)
    assert rec.substeps == per and rec.samples.shape == (rec.steps * per + 1, 2, 3)
    np.testing.assert_array_equal(rec.samples[::per], rec.positions)
    # the metrics judge the samples: no sample pair closer than the reported minimum
    gaps = np.linalg.norm(rec.samples[:, 0] - rec.samples[:, 1], axis=1)
    assert s["min_vehicle_distance"] <= gaps.min() + 1e-12
    assert s["collisions"] == 0 and s["altitude_violations"] == 0 and s["all_reached"]
    # a dip below the floor between two steps counts once for its (vehicle, step)
    rec.samples = rec.samples.copy()
    rec.samples[per + 2, 0, 2] = rec.samples[per + 3, 0, 2] = -0.5
    rec.cache.clear()
    assert summarize(rec)["altitude_violations"] == 1


def test_rotorpy_batched_in_the_loop_flies_as_one_by_one_at_its_rate():
    # the head-on pair of SMALL for 4 s: the scenario key picks the batched model and its
    # 200 Hz; the same decisions' trajectories as one by one at 200 Hz, to RK4's accuracy
    runs = [run_scenario(small(max_time=4.0, dynamics={"model": "rotorpy", **keys}),
                         progress=False)
            for keys in ({"batched": True}, {"substep_rate": 200.0})]
    batched, single = runs
    assert batched.substeps == single.substeps == 40
    assert batched.samples.shape == single.samples.shape == (batched.steps * 40 + 1, 2, 3)
    travelled = np.linalg.norm(batched.positions[-1] - batched.positions[0], axis=1)
    assert travelled.min() > 5.0
    assert np.abs(batched.samples - single.samples).max() < 0.001  # measured 0.007 mm


def test_batched_without_its_extra_is_refused_at_load_naming_the_key(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "torchdiffeq", None)  # as if not installed
    f = tmp_path / "batched.yaml"
    f.write_text(yaml.safe_dump({**SMALL, "dynamics": {"model": "rotorpy", "batched": True}}))
    with pytest.raises(ScenarioError) as err:
        load_scenario(f)
    msg = str(err.value)
    assert msg.startswith(f"{f}: dynamics.batched: needs the [batched] extra (torchdiffeq not ")
    assert "\n" not in msg


def test_rotorpy_commands_stay_within_what_its_velocity_loop_follows_without_flipping():
    # RotorPy's cmd_vel asks for the force m (g - k_v (v - v_cmd)): a gap of g / k_v above the
    # command points it sideways. The selector keeps half of that per period around the real
    # velocity; the simulator lets the commands change by a quarter of it per period.
    sc = small(dynamics={"model": "rotorpy", "vehicle": "hummingbird"})
    m = derive_margins(sc)
    assert m.acceleration == pytest.approx(0.5 * 9.81 / (10.0 * 0.2))
    assert m.command_rate == pytest.approx(0.25 * 9.81 / (10.0 * 0.2))
    reach = m.command_rate * 0.2
    tau = response_time(sc.vehicle_dynamics, 0.2)
    stop = 4.0 * tau + 16.0 / (2 * m.command_rate)
    cap = 10.0 - ALTITUDE_CLEARANCE  # the starts stand 10 m from the floor and the ceiling
    assert m.altitude_margin == pytest.approx(min(stop, cap))
    previous = np.array([[4.0, 0.0, 0.0], [0.0, 0.0, 3.0], [0.0, 0.0, 0.0]])
    u = np.array([[-4.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.2, -0.2, 0.1]])
    out = within_reach(u, previous, m.command_rate, 0.2, np.full(3, 4.0))
    np.testing.assert_allclose(out[0], [4.0 - reach, 0.0, 0.0])
    np.testing.assert_allclose(out[1], [0.0, 0.0, 3.0 - reach])
    np.testing.assert_allclose(out[2], u[2])  # within reach: unchanged
    fast = within_reach(np.array([[4.0, 1.0, 0.0]]), np.array([[4.0, 0.0, 0.0]]), 10.0, 0.2,
                        np.array([4.0]))
    assert np.linalg.norm(fast) == pytest.approx(4.0)  # and never above the speed limit
    first_order = small(dynamics={"model": "first_order", "tau": 1.0})
    assert derive_margins(first_order).command_rate is None  # follows any command linearly


def test_rotorpy_keeps_its_altitude_through_horizontal_manoeuvres_at_the_command_rate():
    """Random horizontal commands, rate-limited as the simulator does and ramped over each
    period: the hummingbird stays within 0.25 m of its altitude (the ceiling-squeeze scenario
    leaves 0.5 m). At twice the rate, stepped, the same commands throw it further than 0.5 m;
    ramped, they do not (docs/results/acceleration-bound.md): the ramp is what keeps it."""
    from vo3d_opt.sim.dynamics import RotorPyDynamics

    sc = small(dynamics={"model": "rotorpy", "vehicle": "hummingbird"})
    rate = derive_margins(sc).command_rate
    rng = np.random.default_rng(7)
    legs = [(rng.uniform(0, 2 * np.pi), rng.uniform(2.0, 4.0), 6) for _ in range(5)]

    def worst_excursion(rate: float, ramp: bool) -> float:
        dyn = RotorPyDynamics("hummingbird", command_ramp=ramp)
        dyn.reset(np.array([[0.0, 0.0, 10.0]]), np.zeros((1, 3)))
        u, dz = np.zeros((1, 3)), 0.0
        for heading, speed, periods in legs:
            target = np.array([[speed * np.cos(heading), speed * np.sin(heading), 0.0]])
            for _ in range(periods):
                u = within_reach(target, u, rate, 0.2, np.array([4.0]))
                r = dyn.step(u, 0.2)
                dz = max(dz, float(np.abs(r.sample_positions[:, 0, 2] - 10.0).max()))
        return dz

    assert worst_excursion(rate, True) < 0.25
    assert worst_excursion(2 * rate, False) > 0.5
    assert worst_excursion(2 * rate, True) < 0.25


def test_rotorpy_commands_of_an_agent_that_does_not_avoid_are_rate_limited_too():
    # The rate limit belongs to the vehicle's velocity loop, not to the selector: an intruder
    # flying straight at its top speed also takes its command in gradually (a step from hover
    # to 4 m/s once put the bundled intruder over the speed limit).
    data = copy.deepcopy(SMALL)
    data["agents"][1]["avoids"] = False
    data["agents"][1]["start"] = [20.0, 30.0, 10.0]  # far apart: nobody needs to avoid
    data["agents"][1]["goal"] = [-20.0, 30.0, 10.0]
    sc = scenario_from_dict({**data, "dynamics": {"model": "rotorpy"}}, "intruder.yaml")
    rec = run_scenario(sc, progress=False, max_steps=25)
    rate = derive_margins(sc).command_rate
    steps = np.diff(np.concatenate([np.zeros((1, 2, 3)), rec.commands[: rec.steps]]), axis=0)
    assert np.abs(steps).max() <= rate * sc.dt + 1e-12
    np.testing.assert_allclose(rec.commands[24, 1], [-4.0, 0.0, 0.0], atol=0.01)  # full speed
    assert summarize(rec)["speed_violations"] == 0
    # a scenario's own acceleration bound below the command rate is the rate the loop keeps
    slow = scenario_from_dict({**data, "dynamics": {"model": "rotorpy"},
                               "safety": {"acceleration": 0.5}}, "intruder.yaml")
    rec = run_scenario(slow, progress=False, max_steps=5)
    assert rec.extra["margins"]["command_rate"] == 0.5
    steps = np.diff(np.concatenate([np.zeros((1, 2, 3)), rec.commands[: rec.steps]]), axis=0)
    assert np.abs(steps).max() <= 0.5 * sc.dt + 1e-12


def test_rotorpy_plans_below_its_top_speed_by_what_its_velocity_loop_overshoots_in_gusts():
    """A hummingbird cruising at its top speed through Dryden gusts flies above it for a moment
    when the selector plans at that speed (``safety.speed_margin: 0``); with the derived margin
    no sample is over it, and every command is the margin below it."""
    data = {"name": "cruise-in-gusts", "dt": 0.2, "max_time": 40.0, "goal_tolerance": 1.0,
            "dynamics": {"model": "rotorpy", "vehicle": "hummingbird"},
            "wind": {"type": "dryden", "velocity": [2.23, 1.97, 0.0]},
            "limits": {"speed": [0.0, 5.0], "altitude": [0.0, 40.0]},
            "defaults": {"r_pz": 5.0, "radius": 0.5, "max_speed": 2.2},
            "agents": [{"id": "a", "start": [0.0, 0.0, 20.0], "goal": [60.0, 0.0, 20.0]}]}
    sc = scenario_from_dict(data)
    margin = derive_margins(sc).speed_margin
    assert margin > 0 and derive_margins(small()).speed_margin == 0.0
    calm = {k: v for k, v in data.items() if k != "wind"}  # no wind: no overshoot, no margin
    assert derive_margins(scenario_from_dict(calm)).speed_margin == 0.0
    rec = run_scenario(sc, progress=False)
    s = summarize(rec)
    assert s["speed_violations"] == 0 and s["all_reached"]
    assert np.linalg.norm(rec.commands, axis=-1).max() <= 2.2 - margin + 1e-9
    at_top = summarize(run_scenario(scenario_from_dict({**data, "safety": {"speed_margin": 0.0}}),
                                    progress=False))
    assert at_top["speed_violations"] > 0


def test_the_speed_margin_reaches_every_decision_path_and_the_command_rate_limit():
    """Planning speeds lowered by the margin in each agent's limits (one select() each), in
    select_many's caps and the batched decisions', and in the simulator's command-rate limit:
    a turn moved into reach there may be faster than either command, and is capped at the
    planning speed (the vehicle here flies its command, to check every one)."""
    from vo3d_opt.sim.batch_select import BatchSelect, Member
    from vo3d_opt.sim.deciders import SwarmSelect
    from vo3d_opt.sim.dynamics import KinematicDynamics
    from vo3d_opt.sim.record import StepDecision

    windy = {"model": "rotorpy", "vehicle": "hummingbird"}
    sc = small(dynamics=windy, wind={"type": "constant", "velocity": [0.0, 3.0, 0.0]})
    margin = derive_margins(sc).speed_margin
    assert margin == pytest.approx(0.1)
    sel, _, _ = scenario_selector(sc)
    assert PerAgentSelect(sc, sel).agent_limits(1).speed[1] == pytest.approx(4.0 - margin)
    swarm = SwarmSelect(sc, sel)
    np.testing.assert_allclose(swarm.top_speeds, 4.0 - margin)
    batch = BatchSelect([Member(sc, swarm, 0, 2)], 2)
    np.testing.assert_allclose(batch.limits[:, 1], 4.0 - margin)
    # calm air, or a slow vehicle: no margin, or at most half its speed
    calm = small(dynamics=windy, wind={"type": "constant", "velocity": [0.0, 0.0, 0.0]})
    assert derive_margins(calm).speed_margin == 0.0
    slow = small(dynamics=windy, wind={"type": "constant", "velocity": [0.0, 3.0, 0.0]},
                 defaults={**SMALL["defaults"], "max_speed": 0.1})
    assert derive_margins(slow).speed_margin == pytest.approx(0.05)
    # decisions at the planning speed, 30 degrees off the x axis, then along it: moved into
    # reach of the last command axis by axis, the turn's command is faster than either
    top = 4.0 - margin

    class Turning:
        formulation = solver = "turning"

        def decide(self, snap):
            heading = np.radians(30.0 if snap.k < 20 else 0.0)
            u = np.tile([top * np.cos(heading), top * np.sin(heading), 0.0], (2, 1))
            return StepDecision(commands=u, statuses=np.full(2, "optimal", dtype=object),
                                decision_times=np.zeros(2), solve_times=np.zeros(2))

        def extra(self):
            return {}

    record = fly(sc, Turning(), dynamics=KinematicDynamics(), progress=False, max_steps=30)
    assert np.linalg.norm(record.commands, axis=-1).max() <= top + 1e-9
