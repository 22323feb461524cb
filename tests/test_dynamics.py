"""Vehicle models of vo3d_opt.sim.dynamics: the simulator's integration bit for bit, and RotorPy
vehicles that hover, track a velocity step, drift in the wind and repeat themselves for a seed."""
from __future__ import annotations

import sys

import numpy as np
import pytest
from pydantic import ValidationError

from vo3d_opt.sim.dynamics import (
    BATCHED_SUBSTEP_RATE,
    DEFAULT_SUBSTEP_RATE,
    BatchedRotorPyDynamics,
    Dynamics,
    StepResult,
    FirstOrderDynamics,
    KinematicDynamics,
    RotorPyDynamics,
    make_dynamics,
)

DT = 0.2


def simulator_integration(starts, commands, arrive_at, dt, tau):
    """A copy of ``Simulator.run``'s integration (before the dynamics module): ``arrive_at[k]``
    marks the agents found arrived after step k; arrived agents are commanded 0 and stop."""
    alpha = None if tau is None else min(1.0, dt / tau)
    p, v = starts.copy(), np.zeros_like(starts)
    done = np.zeros(len(starts), dtype=bool)
    out_p, out_v = [], []
    for k, u in enumerate(commands):
        u = np.where(done[:, None], 0.0, u)
        v = u.copy() if alpha is None else v + (u - v) * alpha
        v[done] = 0.0
        out_v.append(v.copy())
        p = p + v * dt
        done = done | arrive_at[k]
        v[done] = 0.0
        out_p.append(p.copy())
    return np.array(out_p), np.array(out_v)


@pytest.mark.parametrize("tau", [None, 0.15, 0.5, 1.3])
def test_kinematic_and_first_order_match_the_simulator_bit_for_bit(tau):
    rng = np.random.default_rng(7)
    n, steps = 6, 40
    starts = rng.uniform(-50, 50, (n, 3))
    commands = rng.uniform(-4, 4, (steps, n, 3))
    arrive_at = np.zeros((steps, n), dtype=bool)
    arrive_at[[5, 17, 30], [1, 3, 4]] = True
    want_p, want_v = simulator_integration(starts, commands, arrive_at, DT, tau)

    dyn = make_dynamics(None if tau is None else {"model": "first_order", "tau": tau})
    assert isinstance(dyn, KinematicDynamics if tau is None else FirstOrderDynamics)
    dyn.reset(starts)
    held = np.zeros(n, dtype=bool)
    for k in range(steps):
        out = dyn.step(np.where(held[:, None], 0.0, commands[k]), DT)
        assert np.array_equal(out.positions, want_p[k]) and np.array_equal(out.velocities, want_v[k])
        held |= arrive_at[k]
        dyn.hold(arrive_at[k])
    # one straight sample per period: the period's end
    assert out.sample_positions.shape == (1, n, 3) and out.sample_times.tolist() == [DT]


def test_first_order_ignores_commands_of_held_vehicles():
    dyn = FirstOrderDynamics(0.5)
    dyn.reset(np.zeros((2, 3)))
    dyn.step(np.ones((2, 3)), DT)
    dyn.hold([True, False])
    p0 = dyn.positions
    out = dyn.step(np.ones((2, 3)), DT)
    assert np.array_equal(out.positions[0], p0[0]) and np.all(out.velocities[0] == 0)
    assert np.all(out.positions[1] > p0[1])


@pytest.mark.parametrize("spec, wind, key", [
    ({"model": "wobbly"}, None, "model"),
    ({"model": "first_order"}, None, "tau"),
    ({"model": "first_order", "tau": 0.0}, None, "tau"),
    ({"model": "kinematic", "tau": 0.5}, None, "tau"),
    ({"model": "rotorpy", "vehicle": "blimp"}, None, "vehicle"),
    ({"model": "first_order", "tau": 0.5, "vehicle": "crazyflie"}, None, "vehicle"),
    ({"model": "rotorpy", "substep_rate": -5}, None, "substep_rate"),
    ({"model": "rotorpy", "speed": 3}, None, "speed"),
    ({"model": "rotorpy", "command_ramp": "yes"}, None, "command_ramp"),
    ({"model": "first_order", "tau": 0.5, "command_ramp": True}, None, "command_ramp"),
    ({"model": "rotorpy", "batched": "yes"}, None, "batched"),
    ({"model": "kinematic", "batched": True}, None, "batched"),
    ({"model": "rotorpy", "batched": True, "substep_rate": 0}, None, "substep_rate"),
    ({"model": "kinematic"}, {"type": "constant", "velocity": [1, 0, 0]}, "wind"),
    ({"model": "rotorpy"}, {"type": "tornado", "velocity": [1, 0, 0]}, "type"),
    ({"model": "rotorpy"}, {"type": "constant", "velocity": [1, 0]}, "velocity"),
    ({"model": "rotorpy"}, {"type": "constant", "velocity": [1, 0, float("nan")]}, "velocity"),
    ({"model": "rotorpy"}, {"type": "constant", "velocity": [1, 0, 0], "sigma": [1, 1, 1]}, "sigma"),
    ({"model": "rotorpy"}, {"type": "dryden", "velocity": [1, 0, 0], "sigma": [1, -1, 1]}, "sigma"),
])
def test_bad_configuration_is_rejected_naming_the_key(spec, wind, key):
    with pytest.raises(ValueError) as info:
        make_dynamics(spec, wind)
    assert key in named_keys(info.value)


def named_keys(exc: ValueError) -> set[str]:
    """The keys an error names: pydantic's field locations and the ``key: problem`` prefixes."""
    if isinstance(exc, ValidationError):
        return ({str(e["loc"][0]) for e in exc.errors() if e["loc"]}
                | {e["msg"].removeprefix("Value error, ").split(":")[0] for e in exc.errors()})
    return {str(exc).split(":")[0]}


def test_bad_arrays_are_rejected_naming_the_argument():
    dyn = KinematicDynamics()
    with pytest.raises(ValueError, match="^positions:"):
        dyn.reset(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="^positions:"):
        dyn.reset(np.zeros((0, 3)))
    dyn.reset(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="^commands:"):
        dyn.step(np.zeros((2, 3)), DT)
    with pytest.raises(ValueError, match="^commands:"):
        dyn.step(np.full((3, 3), np.nan), DT)
    with pytest.raises(ValueError, match="^dt:"):
        dyn.step(np.zeros((3, 3)), 0.0)
    with pytest.raises(ValueError, match="^mask:"):
        dyn.hold([True])


# ------------------------------------------------------------------------------------ RotorPy


def fly(dyn, commands, periods):
    """Step ``periods`` control periods with constant ``commands``; the StepResults."""
    return [dyn.step(commands, DT) for _ in range(periods)]


@pytest.mark.parametrize("vehicle", ["hummingbird", "crazyflie"])
def test_rotorpy_hover_stays_put(vehicle):
    dyn = make_dynamics({"model": "rotorpy", "vehicle": vehicle})
    start = np.array([[1.0, 2.0, 10.0]])
    dyn.reset(start)
    outs = fly(dyn, np.zeros((1, 3)), 10)
    drift = np.linalg.norm(np.concatenate([o.sample_positions for o in outs]) - start, axis=-1)
    assert drift.max() < 0.01
    assert np.abs(outs[-1].velocities).max() < 0.01


@pytest.mark.parametrize("vehicle, speed", [("hummingbird", 4.0), ("crazyflie", 1.0)])
def test_rotorpy_velocity_step_converges_to_the_command(vehicle, speed):
    """Hover, then a step to ``speed`` along y; RotorPy's controller is a P loop on velocity,
    so the drag leaves a small steady error (about 5 % at these speeds)."""
    dyn = make_dynamics({"model": "rotorpy", "vehicle": vehicle})
    dyn.reset(np.array([[0.0, 0.0, 10.0]]))
    cmd = np.array([[0.0, speed, 0.0]])
    outs = fly(dyn, cmd, 15)
    v = outs[-1].velocities[0]
    assert abs(v[1] - speed) < 0.06 * speed and abs(v[0]) < 0.05 and abs(v[2]) < 0.05
    # still at the end: the last period's samples agree with it
    assert np.ptp(outs[-1].sample_velocities[:, 0, 1]) < 0.01
    # sub-sampled at the default rate, the last sample is the period's end
    assert outs[-1].sample_positions.shape == (round(DT * DEFAULT_SUBSTEP_RATE), 1, 3)
    assert np.array_equal(outs[-1].sample_positions[-1], outs[-1].positions)
    np.testing.assert_allclose(outs[-1].sample_times[-1], DT)


def test_rotorpy_wind_pushes_a_vehicle_commanded_to_stay():
    dyn = make_dynamics({"model": "rotorpy"}, {"type": "constant", "velocity": [3.0, 0.0, 0.0]})
    dyn.reset(np.array([[0.0, 0.0, 10.0]]))
    outs = fly(dyn, np.zeros((1, 3)), 15)
    p, v = outs[-1].positions[0], outs[-1].velocities[0]
    assert p[0] > 0.1 and v[0] > 0.05  # downwind, and still drifting (a velocity loop only)
    assert abs(p[1]) < 0.02 and abs(p[2] - 10.0) < 0.05


def test_rotorpy_hold_stops_a_vehicle_where_it_is():
    dyn = RotorPyDynamics("hummingbird")
    dyn.reset(np.array([[0.0, 0.0, 10.0], [5.0, 0.0, 10.0]]))
    fly(dyn, np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), 3)
    dyn.hold([True, False])
    here = dyn.positions
    out = fly(dyn, np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), 2)[-1]
    assert np.array_equal(out.sample_positions[:, 0], np.repeat(here[:1], len(out.sample_times), 0))
    assert np.all(out.velocities[0] == 0) and out.positions[1, 0] > here[1, 0] + 0.2


@pytest.mark.parametrize("spec", [{"model": "kinematic"}, {"model": "first_order", "tau": 0.5},
                                  {"model": "rotorpy"}, {"model": "rotorpy", "batched": True}])
def test_a_released_vehicle_flies_its_commands_again_from_where_it_was_held(spec):
    dyn = make_dynamics(spec, None, seed=0)
    dyn.reset(np.array([[0.0, 0.0, 10.0], [5.0, 0.0, 10.0]]))
    forward = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    fly(dyn, forward, 2)
    dyn.hold([True, False])
    here = dyn.positions[0]
    fly(dyn, forward, 2)
    assert np.array_equal(dyn.positions[0], here) and dyn.held[0]
    dyn.release([True, False])
    assert not dyn.held.any()
    out = fly(dyn, forward, 5)[-1]
    assert np.all(np.isfinite(out.sample_positions)) and np.all(np.isfinite(out.velocities))
    assert out.positions[0, 0] > here[0] + 0.5 and abs(out.positions[0, 2] - 10.0) < 0.1
    assert out.velocities[0, 0] > 0.3


def dryden_run(seed: int) -> np.ndarray:
    dyn = make_dynamics({"model": "rotorpy", "vehicle": "crazyflie", "substep_rate": 50},
                        {"type": "dryden", "velocity": [1.0, 0.0, 0.0]}, seed=seed)
    dyn.reset(np.array([[0.0, 0.0, 2.0], [3.0, 0.0, 2.0]]))
    samples = []
    for _ in range(5):
        np.random.random(3)  # other users of the global random state do not change the gusts
        samples.append(dyn.step(np.zeros((2, 3)), DT).sample_positions)
    return np.concatenate(samples)


def test_rotorpy_dryden_gusts_repeat_for_a_seed_and_leave_numpy_alone():
    np.random.seed(123)
    a = dryden_run(4)
    after = np.random.random()
    np.random.seed(123)
    np.random.random(3 * 5)
    assert np.random.random() == after  # the caller's global stream went on undisturbed
    assert np.array_equal(a, dryden_run(4))
    b = dryden_run(5)
    assert not np.array_equal(a, b)
    torch = sys.modules.get("torch")  # no placeholder left behind for anyone else
    assert torch is None or hasattr(torch, "__version__")
    # the gusts move the vehicles, differently from each other
    drift = a[-1] - np.array([[0.0, 0.0, 2.0], [3.0, 0.0, 2.0]])
    assert np.abs(drift).max() > 0.005 and not np.allclose(drift[0], drift[1])


#: The commands of paper case 1's UAV 2 (index 1) under RotorPy, its first 19 periods (rounded
#: to mm/s): rate-limited to 0.245 m/s per axis and period, yet as set-point steps they
#: saturated the rotors at period 16 (45 degrees of tilt, 4.75 m/s for at most 3.92 asked).
CASE1_COMMANDS = np.array([
    [-0.245, -0.245, 0.245], [-0.491, -0.491, 0.491], [-0.736, -0.736, 0.584],
    [-0.981, -0.981, 0.573], [-1.226, -1.226, 0.573], [-1.472, -1.472, 0.568],
    [-1.717, -1.717, 0.759], [-1.962, -1.962, 0.892], [-2.207, -1.952, 0.829],
    [-2.452, -1.707, 0.584], [-2.698, -1.539, 0.543], [-2.943, -1.539, 0.788],
    [-3.188, -1.736, 0.543], [-3.434, -1.715, 0.788], [-3.188, -1.96, 0.543],
    [-2.943, -1.715, 0.298], [-3.188, -1.96, 0.053], [-2.943, -1.715, 0.298],
    [-2.698, -1.47, 0.053]])


@pytest.mark.parametrize("ramp", [True, False])
def test_rotorpy_ramped_set_points_keep_case_1_within_its_commanded_speed(ramp):
    dyn = make_dynamics({"model": "rotorpy", "command_ramp": ramp})
    dyn.reset(np.array([[0.0, 0.0, 20.0]]))
    fastest = max(np.linalg.norm(dyn.step(u[None], DT).sample_velocities, axis=-1).max()
                  for u in CASE1_COMMANDS)
    asked = np.linalg.norm(CASE1_COMMANDS, axis=1).max()
    if ramp:
        assert fastest <= asked
    else:  # the set-point steps: what the ramp is for
        assert fastest > asked + 0.5


def test_rotorpy_ramp_reaches_the_command_by_the_period_end_and_holds_it():
    ramped = make_dynamics({"model": "rotorpy"})
    stepped = make_dynamics({"model": "rotorpy", "command_ramp": False})
    for dyn in (ramped, stepped):
        dyn.reset(np.array([[0.0, 0.0, 10.0]]))
    u = np.array([[1.0, 0.0, 0.0]])
    a, b = ramped.step(u, DT), stepped.step(u, DT)
    # the first sub-step asks for 1/20 of the command: the ramped vehicle starts slower
    assert a.sample_velocities[0, 0, 0] < 0.2 * b.sample_velocities[0, 0, 0]
    np.testing.assert_allclose(ramped.setpoints, u)
    for _ in range(20):
        a = ramped.step(u, DT)
    np.testing.assert_allclose(a.velocities[0], u[0], atol=0.05)
    ramped.hold([True])
    assert np.all(ramped.setpoints == 0.0)


# ------------------------------------------------------------------------- RotorPy, batched


def paired_runs(
    wind: dict | None, seed: int = 0, periods: int = 8
) -> tuple[list[Dynamics], list[list[StepResult]]]:
    """The same three vehicles, commands and wind flown one by one (RK45) and batched (RK4),
    both at the batched model's sub-step rate; vehicle 1 is held after half the periods."""
    rng = np.random.default_rng(11)
    starts = rng.uniform(0.0, 30.0, (3, 3)) + [0.0, 0.0, 10.0]
    # a random walk of set-points, 0.5 m/s per axis and period at most: twice the simulator's
    # rate limit for the hummingbird (a set-point jump of several m/s makes it tumble, where
    # the two integrations part ways)
    commands = np.clip(np.cumsum(rng.uniform(-0.5, 0.5, (periods, 3, 3)), axis=0), -3.0, 3.0)
    models = [make_dynamics({"model": "rotorpy", "substep_rate": BATCHED_SUBSTEP_RATE}, wind,
                            seed=seed),
              make_dynamics({"model": "rotorpy", "batched": True}, wind, seed=seed)]
    runs = []
    for dyn in models:
        dyn.reset(starts)
        outs = []
        for k in range(periods):
            if k == periods // 2:
                dyn.hold([False, True, False])
            outs.append(dyn.step(commands[k], DT))
        runs.append(outs)
    return models, runs


@pytest.mark.parametrize("wind", [None, {"type": "constant", "velocity": [3.0, 0.0, 0.0]},
                                  {"type": "dryden", "velocity": [2.0, 1.0, 0.0]}])
def test_batched_vehicles_fly_as_the_one_by_one_ones(wind):
    models, (single, batched) = paired_runs(wind)
    assert isinstance(models[1], BatchedRotorPyDynamics)
    for a, b in zip(single, batched, strict=True):
        assert np.array_equal(a.sample_times, b.sample_times)
        # RK4 at 200 Hz against RK45 (itself within rtol 1e-3), the same gusts: measured
        # 0.08 mm and 0.6 mm/s at most; gusts out of step gave 3.1 mm and 3.3 mm/s
        assert np.abs(a.sample_positions - b.sample_positions).max() < 0.001
        assert np.abs(a.sample_velocities - b.sample_velocities).max() < 0.002
    moved = batched[-1].positions - batched[0].positions
    assert np.linalg.norm(moved[[0, 2]], axis=1).min() > 0.5  # they did fly
    held = batched[len(batched) // 2].sample_positions[0, 1]
    for out in batched[len(batched) // 2:]:  # the held vehicle stays where it was stopped
        still = np.repeat(held[None], len(out.sample_times), 0)
        assert np.array_equal(out.sample_positions[:, 1], still)
        assert np.all(out.sample_velocities[:, 1] == 0)


def batched_run(seed: int) -> list[StepResult]:
    dyn = make_dynamics({"model": "rotorpy", "batched": True},
                        {"type": "dryden", "velocity": [1.0, 0.0, 0.0]}, seed=seed)
    dyn.reset(np.array([[0.0, 0.0, 5.0], [4.0, 0.0, 5.0]]))
    return [dyn.step(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), DT) for _ in range(3)]


def test_batched_vehicles_repeat_for_a_seed_and_leave_the_random_streams_alone():
    import torch

    torch.manual_seed(7)
    np.random.seed(7)
    first = batched_run(3)
    after = torch.rand(3), np.random.random(3)
    torch.manual_seed(7)
    np.random.seed(7)
    assert np.array_equal(after[0], torch.rand(3))  # the callers' streams were not drawn from
    assert np.array_equal(after[1], np.random.random(3))
    again = batched_run(3)
    for a, b in zip(first, again, strict=True):
        assert np.array_equal(a.sample_positions, b.sample_positions)
    other = batched_run(4)  # other gusts
    assert not np.array_equal(other[-1].positions, first[-1].positions)


def test_batched_refuses_the_one_by_one_integrator_options():
    with pytest.raises(ValueError, match="^integrator_kwargs:"):
        make_dynamics({"model": "rotorpy", "batched": True},
                      integrator_kwargs={"method": "RK45", "rtol": 1e-6})


def test_batched_without_its_extra_names_the_key_and_how_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "torchdiffeq", None)  # as if not installed
    with pytest.raises(ValueError) as info:  # the configuration, before any import of torch
        make_dynamics({"model": "rotorpy", "batched": True})
    assert named_keys(info.value) >= {"batched"}
    assert "(torchdiffeq not installed)" in str(info.value) and "vo3d-opt[batched]" in str(info.value)
    with pytest.raises(ImportError, match=r"^dynamics\.batched: needs the \[batched\] extra \(torchdiffeq"):
        BatchedRotorPyDynamics()  # the model built directly
