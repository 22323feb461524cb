"""The simulator's preferred velocities: straight at the goal, and the detour out of a stall."""
from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt.sim.traffic import STALL_TIME, GoalWithDetours, goal_velocity, keep_watch

DT = 0.2
GOALS = np.array([[100.0, 0.0, 20.0], [0.0, 100.0, 10.0]])


def fly_rule(rule: GoalWithDetours, positions: list[np.ndarray]) -> np.ndarray:
    return np.array([rule(p) for p in positions])


def test_an_agent_that_keeps_moving_towards_its_goal_never_detours():
    rule = GoalWithDetours(GOALS, 4.0, DT)
    p, out = np.zeros((2, 3)), []
    for _ in range(200):  # 40 s at 1 m/s: a quarter of top speed, well above the stall share
        w = rule(p)
        out.append(np.allclose(w, goal_velocity(p, GOALS, 4.0, DT)))
        p = p + 0.25 * w * DT
    assert all(out)


def test_a_stalled_agent_turns_right_at_full_speed_then_seeks_its_goal_again():
    rule = GoalWithDetours(GOALS, 4.0, DT)
    p = np.array([[0.0, 0.0, 20.0], [0.0, 0.0, 10.0]])
    still = fly_rule(rule, [p] * int(3 * STALL_TIME / DT + 1))  # held in place for 3 periods
    steps = np.arange(still.shape[0]) * DT
    straight = goal_velocity(p, GOALS, 4.0, DT)
    detour = (steps >= STALL_TIME - 1e-9) & (steps < 2 * STALL_TIME - 1e-9)
    # first the goal, then the goal direction turned 90° clockwise seen from above
    before = steps < STALL_TIME - 1e-9
    np.testing.assert_allclose(still[before], np.broadcast_to(straight, (before.sum(), 2, 3)))
    right = np.array([[0.0, -4.0, 0.0], [4.0, 0.0, 0.0]])
    np.testing.assert_allclose(still[detour], np.broadcast_to(right, (detour.sum(), 2, 3)),
                               atol=1e-12)
    # after the detour the goal again, and it is judged afresh for a whole stall time
    after = (steps >= 2 * STALL_TIME - 1e-9) & (steps < 3 * STALL_TIME - 1e-9)
    np.testing.assert_allclose(still[after], np.broadcast_to(straight, (after.sum(), 2, 3)))


def test_two_watchers_with_goals_in_each_others_buffer_both_get_home():
    """Two vehicles hovering at goals 1.05 r_pz apart (inside each other's buffer, outside its
    inner half) decide again while traffic that does not avoid passes: neither pushes the other
    off its goal for good, and both are home at the end."""
    from vo3d_opt.sim.metrics import summarize
    from vo3d_opt.sim.scenario import scenario_from_dict
    from vo3d_opt.sim.simulator import run_scenario

    data = {"name": "two-watchers", "dt": 0.2, "max_time": 60.0, "goal_tolerance": 0.3,
            "sensing": {"vehicle_range": 40.0},
            "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
            "defaults": {"r_pz": 10.0, "radius": 0.5, "max_speed": 4.0},
            "agents": [{"id": "a", "start": [0.0, 0.0, 20.0], "goal": [0.0, 0.0, 20.0]},
                       {"id": "b", "start": [10.5, 0.0, 20.0], "goal": [10.5, 0.0, 20.0]},
                       {"id": "c", "start": [-60.0, 30.0, 20.0], "goal": [60.0, 30.0, 20.0],
                        "avoids": False}]}
    record = run_scenario(scenario_from_dict(data, "two-watchers.yaml"), progress=False)
    s = summarize(record)
    assert (record.decided[:, :2] & record.arrived[:-1, :2]).any()  # they kept watch
    assert s["all_reached"] and s["collisions"] == 0


def test_an_agent_is_stuck_while_on_a_detour_and_only_then():
    """``stuck`` (read before each call, as the simulator's keep_watch does) is the agents whose
    detour, begun at an earlier call, goes on at this one."""
    rule = GoalWithDetours(GOALS, 4.0, DT)
    p = np.array([[0.0, 0.0, 20.0], [0.0, 0.0, 10.0]])
    straight = goal_velocity(p, GOALS, 4.0, DT)
    was, seen = np.zeros(2, dtype=bool), np.zeros(2, dtype=bool)
    for _ in range(int(3 * STALL_TIME / DT + 1)):
        stuck = rule.stuck.copy()
        detour = ~np.all(np.isclose(rule(p), straight), axis=1)
        assert np.array_equal(stuck, detour & was)
        was, seen = detour, seen | stuck
    assert seen.all()
    moving = GoalWithDetours(GOALS, 4.0, DT)
    for k in range(int(3 * STALL_TIME / DT)):
        assert not moving.stuck.any()
        moving(p + straight * DT * k)


def _turned_right(w: np.ndarray, deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    return np.stack([c * w[:, 0] + s * w[:, 1], -s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=1)


def test_detours_in_a_row_turn_further_each_time_then_start_again():
    """Held in place: each stall window (STALL_TIME) after a detour ends in another detour,
    turned 90°, 180°, 270°, then 90° again (DETOUR_TURNS), each for STALL_TIME; the goal in
    between."""
    rule = GoalWithDetours(GOALS, 4.0, DT)
    p = np.array([[0.0, 0.0, 20.0], [0.0, 0.0, 10.0]])
    still = fly_rule(rule, [p] * int(8.5 * STALL_TIME / DT))
    straight = goal_velocity(p, GOALS, 4.0, DT)
    turns = []  # the turn of each run of equal velocities, in order
    for w in still:
        deg = next((d for d in (0.0, 90.0, 180.0, 270.0)
                    if np.allclose(w, _turned_right(straight, d), atol=1e-12)), None)
        assert deg is not None, w
        if not turns or turns[-1][0] != deg:
            turns.append([deg, 0])
        turns[-1][1] += 1
    assert [d for d, _ in turns] == [0.0, 90.0, 0.0, 180.0, 0.0, 270.0, 0.0, 90.0, 0.0]
    assert all(abs(k * DT - STALL_TIME) <= DT + 1e-9 for _, k in turns[1:-1]), turns


def test_a_window_without_a_stall_starts_the_detours_count_afresh():
    rule = GoalWithDetours(GOALS[:1], 4.0, DT)
    p = np.array([[0.0, 0.0, 20.0]])
    fly_rule(rule, [p] * round(2 * STALL_TIME / DT))  # a first detour (90°), then the goal
    for _ in range(round(STALL_TIME / DT)):  # a window of real progress towards the goal
        w = rule(p)
        p = p + w * DT
    w = fly_rule(rule, [p] * round(1.5 * STALL_TIME / DT))  # stalled again: 90°, not 180°
    straight = goal_velocity(p, GOALS[:1], 4.0, DT)
    first = next(x for x in w if not np.allclose(x, straight))
    np.testing.assert_allclose(first, _turned_right(straight, 90.0), atol=1e-12)


def test_the_first_detour_is_the_right_turn_as_before_bit_for_bit():
    """The first of a row turns by cos/sin of the detour angle itself, as the single-turn rule
    did (a run with no second detour in a row is unchanged)."""
    rule = GoalWithDetours(GOALS, 4.0, DT)
    w = np.array([[3.0, -1.0, 0.5], [0.1, 2.0, -0.3]])
    v_max = np.array([4.0, 4.0])
    turn = np.deg2rad(90.0)
    c, s = np.cos(turn), np.sin(turn)
    old = np.stack([c * w[:, 0] + s * w[:, 1], -s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=1)
    old = old * (v_max / np.linalg.norm(old, axis=1))[:, None]
    assert np.array_equal(rule._detour(w, v_max, np.array([1, 1])), old)


def test_waiting_at_the_goal_starts_the_detours_count_afresh():
    """An agent that detoured, then waited at its goal's door (within ``near``: no detour
    there), turns 90° again when it stalls farther off, not 180°."""
    rule = GoalWithDetours(GOALS[:1], 4.0, DT, near=10.0)
    far = np.array([[0.0, 0.0, 20.0]])
    fly_rule(rule, [far] * round(STALL_TIME / DT + 2))  # stalled: a first detour (90°) begins
    assert rule.in_row[0] == 1
    door = GOALS[:1] - np.array([[5.0, 0.0, 0.0]])  # 5 m from the goal: within near
    # there from within the detour: its window starts at the door, and stalls there
    fly_rule(rule, [door] * round(2.5 * STALL_TIME / DT))
    assert rule.waiting[0] and rule.in_row[0] == 0
    w = fly_rule(rule, [far] * round(2.5 * STALL_TIME / DT))  # pushed off and stalled again
    straight = goal_velocity(far, GOALS[:1], 4.0, DT)
    first = next(x for x in w if not np.allclose(x, straight))
    np.testing.assert_allclose(first, _turned_right(straight, 90.0), atol=1e-12)


def test_the_detour_keeps_the_vertical_part_and_the_top_speed():
    rule = GoalWithDetours(GOALS[:1], 3.0, DT, stall_time=1.0)
    p = np.array([[0.0, 0.0, 0.0]])  # the goal is up and ahead
    w = fly_rule(rule, [p] * 6)[-1, 0]
    assert np.linalg.norm(w) == pytest.approx(3.0)
    assert w[0] == pytest.approx(0.0, abs=1e-12) and w[1] < 0 and w[2] > 0


@pytest.mark.parametrize("kwargs,name", [({"stall_time": 0.0}, "stall_time"),
                                         ({"detour_deg": float("nan")}, "detour_deg")])
def test_bad_detour_settings_are_refused_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        GoalWithDetours(GOALS, 4.0, DT, **kwargs)


def test_an_agent_circling_its_goal_is_not_stalled():
    """Under a 1 s lag an agent may overshoot its goal and circle it for a while (the
    first-order random-crossing-1000 once left one so): it makes no progress but moves, and a
    detour would only send it further off."""
    rule = GoalWithDetours(GOALS[:1], 4.0, DT)
    angles = np.arange(100) * 0.1  # 3 m from the goal, 0.3 m per period (1.5 m/s)
    ring = GOALS[0] + 3.0 * np.stack([np.cos(angles), np.sin(angles), 0 * angles], axis=1)
    w = fly_rule(rule, [q[None] for q in ring])[:, 0]
    np.testing.assert_allclose(w, goal_velocity(ring, np.tile(GOALS[0], (100, 1)), 4.0, DT))


def test_an_agent_stalled_near_its_goal_waits_instead_of_detouring():
    rule = GoalWithDetours(GOALS, 4.0, DT, near=[10.0, 1.0])
    p = GOALS - np.array([[5.0, 0.0, 0.0], [5.0, 0.0, 0.0]])  # both 5 m short, held there
    w = fly_rule(rule, [p] * int(1.5 * STALL_TIME / DT))
    straight = goal_velocity(p, GOALS, 4.0, DT)
    np.testing.assert_allclose(w[:, 0], np.broadcast_to(straight[0], (w.shape[0], 3)))
    assert not np.allclose(w[-1, 1], straight[1])  # beyond its 1 m: the detour


def test_only_an_agent_stalled_within_near_of_its_goal_is_waiting():
    rule = GoalWithDetours(GOALS, 4.0, DT, near=[10.0, 1.0])
    p = GOALS - np.array([[5.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    fly_rule(rule, [p] * int(0.5 * STALL_TIME / DT))
    assert not rule.waiting.any()  # not stalled yet
    fly_rule(rule, [p] * int(STALL_TIME / DT))
    np.testing.assert_array_equal(rule.waiting, [True, False])


def test_an_agent_pushed_off_its_goals_door_is_no_longer_waiting():
    rule = GoalWithDetours(GOALS, 4.0, DT, near=[10.0, 10.0])
    p = GOALS - np.array([[5.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    fly_rule(rule, [p] * int(1.5 * STALL_TIME / DT))
    assert rule.waiting.all()
    pushed = p - np.array([[0.0, 0.0, 0.0], [20.0, 0.0, 0.0]])
    fly_rule(rule, [pushed])
    np.testing.assert_array_equal(rule.waiting, [True, False])


# ---------------------------------------------------------------- arrived agents keep watch


def brute_watch(p, goals, done, straight, watching, tol, vrange, run, stuck=None):
    stuck = np.zeros(len(p), dtype=bool) if stuck is None else stuck
    out = np.zeros(len(p), dtype=bool)
    for i in range(len(p)):
        if not done[i] or straight[i]:
            continue
        near = any((straight[j] or stuck[j]) and not done[j] and run[j] == run[i]
                   and np.linalg.norm(p[i] - p[j]) <= vrange[i] for j in range(len(p)))
        away = np.linalg.norm(p[i] - goals[i]) > tol[i]
        out[i] = near or (watching[i] and away)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_keep_watch_is_the_pairwise_rule_within_each_run(seed):
    rng = np.random.default_rng(seed)
    n = 40
    p = rng.uniform(-60.0, 60.0, (n, 3))
    goals = p + rng.normal(0.0, 1.0, (n, 3))
    kw = dict(done=rng.random(n) < 0.6, straight=rng.random(n) < 0.2,
              watching=rng.random(n) < 0.3, tolerance=np.full(n, 1.0),
              vehicle_range=rng.choice([20.0, 45.0, np.inf], n), run=rng.integers(0, 4, n))
    got = keep_watch(p, goals, **kw)
    want = brute_watch(p, goals, kw["done"], kw["straight"], kw["watching"], kw["tolerance"],
                       kw["vehicle_range"], kw["run"])
    assert np.array_equal(got, want) and got.any() and not got.all()
    alone = dict(kw, run=None)
    want = brute_watch(p, goals, kw["done"], kw["straight"], kw["watching"], kw["tolerance"],
                       kw["vehicle_range"], np.zeros(n))
    assert np.array_equal(keep_watch(p, goals, **alone), want)
    # a cooperative agent on a detour from a stall wakes the arrived ones near it too
    stuck = rng.random(n) < 0.3
    want = brute_watch(p, goals, kw["done"], kw["straight"], kw["watching"], kw["tolerance"],
                       kw["vehicle_range"], kw["run"], stuck)
    assert np.array_equal(keep_watch(p, goals, **kw, stuck=stuck), want)
    calm = dict(kw, straight=np.zeros(n, dtype=bool), watching=np.zeros(n, dtype=bool))
    got = keep_watch(p, goals, **calm, stuck=stuck)
    assert got.any() and not keep_watch(p, goals, **calm).any()
    assert np.array_equal(got, brute_watch(p, goals, calm["done"], calm["straight"],
                                           calm["watching"], kw["tolerance"],
                                           kw["vehicle_range"], kw["run"], stuck))
    lost = p.copy()
    lost[np.flatnonzero(kw["straight"] & ~kw["done"])] = np.nan  # no threat flies on
    assert np.array_equal(keep_watch(lost, goals, **kw),
                          kw["watching"] & kw["done"] & ~kw["straight"]
                          & (np.linalg.norm(p - goals, axis=1) > 1.0))


def test_a_watcher_released_from_hover_ramps_its_command_up_from_zero():
    """Under a rate-limited command interface (RotorPy's), an agent that arrives at speed stops
    dead and hovers; kept watching, it flies again from hover, so its first command after the
    release is within one period's reach of 0, not of its last command before it arrived (a
    set-point step many times the limit flipped a RotorPy vehicle). Every command stays within
    reach of the vehicle's own velocity before the step (here the vehicle flies its command)."""
    from vo3d_opt.sim.dynamics import KinematicDynamics
    from vo3d_opt.sim.safety import command_rate
    from vo3d_opt.sim.scenario import scenario_from_dict
    from vo3d_opt.sim.simulator import Simulator, fly, scenario_selector

    data = {"name": "released-watcher", "dt": 0.1, "max_time": 40.0, "goal_tolerance": 0.5,
            "sensing": {"vehicle_range": 40.0},
            "dynamics": {"model": "rotorpy", "vehicle": "hummingbird"},
            "limits": {"speed": [0.0, 2.5], "altitude": [0.0, 40.0]},
            "defaults": {"r_pz": 1.0, "radius": 0.2, "max_speed": 2.5},
            "agents": [{"id": "a", "start": [0.0, 0.0, 20.0], "goal": [20.0, 0.0, 20.0]},
                       {"id": "c", "start": [25.0, -45.0, 20.0], "goal": [25.0, 45.0, 20.0],
                        "avoids": False}]}
    sc = scenario_from_dict(data, "released-watcher.yaml")
    reach = command_rate(sc) * sc.dt

    class Checked(KinematicDynamics):
        def _step(self, u, dt):
            gap = np.abs(u - self._v)[~self._held]
            assert (gap <= reach + 1e-9).all(), f"a command {gap.max():.2f} m/s from the velocity"
            return super()._step(u, dt)

    selector, _, _ = scenario_selector(sc)
    record = fly(sc, Simulator(sc, selector).step, dynamics=Checked(), progress=False)
    home = record.arrived[:-1, 0]
    first = int(np.argmax(home))  # the step after it arrived: released at once
    assert home.any() and record.decided[first, 0]
    assert np.abs(record.commands[home & ~record.decided[:, 0], 0]).max() == 0.0  # in hover
