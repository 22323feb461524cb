"""Batched RotorPy vehicles of many runs in one fleet (vo3d_opt.sim.rotorpy_fleet): each run's
numbers are those of the run flown alone, bit for bit, and no run waits for one that is over."""

import threading
import time

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("rotorpy")

from vo3d_opt.sim.dynamics import make_dynamics  # noqa: E402
from vo3d_opt.sim.metrics import summarize  # noqa: E402
from vo3d_opt.sim.record import StepDecision  # noqa: E402
from vo3d_opt.sim.rotorpy_fleet import FleetAborted, FleetStepError, RotorPyFleet  # noqa: E402
from vo3d_opt.sim.scenario import scenario_from_dict, scenario_variant  # noqa: E402
from vo3d_opt.sim.simulator import fly, scenario_dynamics  # noqa: E402
from vo3d_opt.sweep import flight  # noqa: E402

BATCHED = {"model": "rotorpy", "batched": True}
WINDS = [None, {"type": "constant", "velocity": [2.0, 0.0, 0.0]},
         {"type": "dryden", "velocity": [1.0, 1.0, 0.0]}]


def _case(j: int, periods: int) -> dict:
    """Run j: 2 + j vehicles, its own wind, seed, commands and length; vehicle 0 (run 1: all)
    held from period 2 to 5 (hold and release inside the fleet)."""
    rng = np.random.default_rng(j)
    n = 2 + j
    return {"n": n, "wind": WINDS[j % 3], "seed": j, "starts": rng.normal(size=(n, 3)) * 5,
            "commands": rng.uniform(-3, 3, size=(periods, n, 3))}


def _flown(case: dict, dyn) -> list[np.ndarray]:
    dyn.reset(case["starts"])
    out = []
    # run 1 holds all of its vehicles (it asks with none to step while the others fly)
    hold = np.arange(case["n"]) == 0 if case["seed"] != 1 else np.ones(case["n"], dtype=bool)
    for k, u in enumerate(case["commands"]):
        if k == 2:
            dyn.hold(hold)
        if k == 5:
            dyn.release(hold)
        step = dyn.step(u, 0.2)
        out += [step.sample_positions.copy(), step.sample_velocities.copy()]
    return out


def _in_threads(cases: list[dict], fleet: RotorPyFleet) -> list[list[np.ndarray]]:
    models = [make_dynamics(BATCHED, c["wind"], seed=c["seed"], fleet=fleet) for c in cases]
    out: list = [None] * len(cases)
    errors: list = []

    def one(i: int) -> None:
        try:
            out[i] = _flown(cases[i], models[i])
        except Exception as exc:  # noqa: BLE001 - reported below
            errors.append(exc)
        finally:
            models[i].leave()

    _join_all([threading.Thread(target=one, args=(i,), daemon=True) for i in range(len(cases))])
    assert not errors, errors
    return out


def _join_all(threads: list[threading.Thread], seconds: float = 120.0) -> None:
    """Start the threads and wait for all, at most ``seconds`` in all (daemons: a run that
    waits for ever fails the test without keeping pytest from exiting)."""
    for t in threads:
        t.start()
    deadline = time.monotonic() + seconds
    for t in threads:
        t.join(timeout=max(0.0, deadline - time.monotonic()))
    assert not any(t.is_alive() for t in threads), "a run waits for ever"


def test_runs_in_a_fleet_fly_as_each_alone_bit_for_bit():
    # runs of different lengths (the short ones leave while the others fly), winds, seeds
    cases = [_case(j, periods) for j, periods in enumerate((7, 3, 8, 1, 6))]
    alone = [_flown(c, make_dynamics(BATCHED, c["wind"], seed=c["seed"])) for c in cases]
    fleet = RotorPyFleet()
    together = _in_threads(cases, fleet)
    assert max(fleet._vehicles) > max(c["n"] for c in cases)  # runs stepped in one call
    for a, b in zip(alone, together, strict=True):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert np.array_equal(x, y)
    assert not np.array_equal(alone[0][-2], alone[2][-2][:, :2])  # they are different runs


def test_a_fleet_refuses_a_second_vehicle_type_and_a_model_that_left():
    fleet = RotorPyFleet()
    dyn = make_dynamics(BATCHED, fleet=fleet)
    with pytest.raises(ValueError, match="vehicle"):
        make_dynamics({**BATCHED, "vehicle": "crazyflie"}, fleet=fleet)
    dyn.reset(np.zeros((1, 3)))
    dyn.leave()
    with pytest.raises(RuntimeError, match="left"):
        dyn.step(np.zeros((1, 3)), 0.2)


def test_periods_of_different_length_fail_every_run_of_the_step_none_hangs():
    fleet = RotorPyFleet()
    models = [make_dynamics(BATCHED, fleet=fleet) for _ in range(2)]
    errors: list = []

    def one(i: int, dt: float) -> None:
        try:
            models[i].reset(np.zeros((1, 3)) + i)
            models[i].step(np.zeros((1, 3)), dt)
        except FleetStepError as exc:
            assert isinstance(exc.__cause__, ValueError)
            errors.append(str(exc))
        finally:
            models[i].leave()

    _join_all([threading.Thread(target=one, args=(i, dt), daemon=True)
               for i, dt in enumerate((0.2, 0.1))])
    assert len(errors) == 2 and all("dt:" in e for e in errors)


def test_an_aborted_fleet_ends_every_run_at_its_next_period():
    """``abort`` (a Ctrl-C of the thread that started the runs): each run, waiting or asking
    for its next period, gets FleetAborted at once instead of flying to its end."""
    fleet = RotorPyFleet()
    models = [make_dynamics(BATCHED, fleet=fleet) for _ in range(2)]
    flown, ended = [0, 0], []

    def one(i: int) -> None:
        try:
            models[i].reset(np.zeros((1, 3)) + 5.0 * i)
            for _ in range(100_000):  # hours of flight
                models[i].step(np.zeros((1, 3)), 0.2)
                flown[i] += 1
        except FleetAborted:
            ended.append(i)
        finally:
            models[i].leave()

    threads = [threading.Thread(target=one, args=(i,), daemon=True) for i in range(2)]
    for t in threads:
        t.start()
    while min(flown) < 3:
        time.sleep(0.01)
    fleet.abort()
    for t in threads:
        t.join(timeout=30.0)
    assert sorted(ended) == [0, 1] and max(flown) < 1000


def test_a_ctrl_c_while_a_sweep_task_waits_for_its_fleet_ends_the_runs(monkeypatch):
    """A KeyboardInterrupt in the thread waiting for the fleet's runs goes up, and the runs'
    threads end with it (else they would fly on to their ends, and the process with them)."""
    from concurrent.futures import Future

    before = set(threading.enumerate())
    ends: list[str] = []
    member = flight._fly_member

    def spied(*args):
        try:
            member(*args)
            ends.append("landed")
        except FleetAborted:
            ends.append("aborted")

    stepped, step_all = threading.Event(), RotorPyFleet._fly_all

    def counted(self, batch, periods):
        step_all(self, batch, periods)
        stepped.set()

    def interrupted(self, timeout=None):
        assert stepped.wait(60.0)  # the runs are flying (for 10 minutes of flight)
        raise KeyboardInterrupt

    waiting = _waiting(2)
    for w in waiting:
        w.sc = scenario_variant(w.sc, max_time=600.0)
    monkeypatch.setattr(RotorPyFleet, "_fly_all", counted)
    monkeypatch.setattr(flight, "_fly_member", spied)
    monkeypatch.setattr(Future, "result", interrupted)
    with pytest.raises(KeyboardInterrupt):
        flight._fleet_outcomes(waiting)

    def flying() -> set:  # the pool's threads, which the process would wait for at exit
        return {t for t in threading.enumerate() if not t.daemon} - before

    deadline = time.monotonic() + 30.0
    while flying() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not flying() and ends == ["aborted", "aborted"]


def _scenario(j: int) -> dict:
    rng = np.random.default_rng(10 + j)
    y = float(rng.uniform(-0.5, 0.5))
    return {
        "name": f"fleet-{j}",
        "dt": 0.2,
        "max_time": 1.0 + 0.4 * j,
        "limits": {"speed": [0.0, 3.0], "altitude": [0.0, 40.0]},
        "defaults": {"r_pz": 2.0},
        "dynamics": BATCHED,
        "wind": WINDS[j % 3],
        "sensing": {"seed": j},
        "agents": [
            {"id": "a", "start": [-5.0, y, 10.0], "goal": [5.0, 0.0, 10.0]},
            {"id": "b", "start": [5.0, 0.0, 10.0], "goal": [-5.0, y, 10.0]},
        ],
    }


class _Failing:
    """A decision step that raises at its third decision, else the wrapped one's."""

    def __init__(self, step) -> None:
        self.step, self.calls = step, 0

    def __getattr__(self, name):
        return getattr(self.step, name)

    def decide(self, snap) -> StepDecision:
        self.calls += 1
        if self.calls == 3:
            raise RuntimeError("decision failed on purpose")
        return self.step.decide(snap)


def _waiting(count: int) -> list:
    out = []
    for j in range(count):
        sc = scenario_from_dict({k: v for k, v in _scenario(j).items() if v is not None})
        assert flight.in_fleet(sc)
        sc, step, options = flight.flown(sc, flight.Method())
        out.append(flight._Waiting({"index": j, "error": None}, sc, step, options, 0.0))
    return out


def _row_alone(w) -> dict:
    """The row of ``w``'s encounter flown alone (its own batched model, no fleet)."""
    alone = fly(w.sc, flight.flown(w.sc, flight.Method())[1], progress=False)
    row = {"index": w.row["index"], "error": None}
    flight._summarised(row, alone, {**summarize(alone), "selector_options": w.options})
    return row


def _same_rows(row: dict, expected: dict) -> None:
    keys = [k for k in expected if k not in flight.TIMING_COLUMNS]
    assert len(keys) > 10
    assert {k: row[k] for k in keys} == {k: expected[k] for k in keys}
    assert row["run_time"] >= 0 and row["worker"]


def test_a_sweep_task_flies_its_encounters_in_a_fleet_with_the_rows_of_each_alone():
    waiting = _waiting(3)
    waiting[1].step = _Failing(waiting[1].step)
    flight._fly_in_fleet(waiting, flight.Method())
    assert "decision failed on purpose" in waiting[1].row["error"]
    for j in (0, 2):
        _same_rows(waiting[j].row, _row_alone(waiting[j]))


def test_a_failed_fleet_step_flies_each_encounter_again_alone(monkeypatch):
    made = []

    def dynamics(sc, fleet=None):
        model = scenario_dynamics(sc, fleet=fleet)
        if fleet is not None and not made:  # the first run's winds fail once, in the fleet
            model.period_winds = lambda period: (_ for _ in ()).throw(OSError("wind lost"))
        made.append(model)
        return model

    alone = []

    def fly_alone(sc, step, **kwargs):
        if kwargs.get("dynamics") is None:
            alone.append(sc.name)
        return fly(sc, step, **kwargs)

    waiting = _waiting(3)
    monkeypatch.setattr(flight, "scenario_dynamics", dynamics)
    monkeypatch.setattr(flight, "fly", fly_alone)
    flight._fly_in_fleet(waiting, flight.Method())
    monkeypatch.undo()
    assert sorted(alone) == ["fleet-0", "fleet-1", "fleet-2"]  # the fleet failed: each again
    for w in waiting:
        assert w.row["error"] is None
        _same_rows(w.row, _row_alone(w))


def test_a_model_alone_raises_its_own_error_not_a_fleet_error():
    dyn = make_dynamics(BATCHED, {"type": "dryden", "velocity": [1.0, 0.0, 0.0]})
    dyn.reset(np.zeros((2, 3)))
    dyn.period_winds = lambda period: (_ for _ in ()).throw(KeyError("gust"))
    with pytest.raises(KeyError, match="gust"):
        dyn.step(np.zeros((2, 3)), 0.2)


def test_a_run_that_cannot_be_set_up_does_not_hold_up_the_others(monkeypatch):
    def dynamics(sc, fleet=None):
        if sc.name == "fleet-1":
            raise ValueError("dynamics: refused on purpose")
        return scenario_dynamics(sc, fleet=fleet)

    waiting = _waiting(3)
    monkeypatch.setattr(flight, "scenario_dynamics", dynamics)
    flight._fly_in_fleet(waiting, flight.Method())
    monkeypatch.undo()
    assert "refused on purpose" in waiting[1].row["error"]
    for j in (0, 2):
        _same_rows(waiting[j].row, _row_alone(waiting[j]))


def test_the_sweep_refuses_the_rotorpy_family_without_torch_naming_the_extra(monkeypatch):
    from vo3d_opt import extras
    from vo3d_opt.sweep.runner import SweepError, validate

    real = extras.installed
    monkeypatch.setattr(extras, "installed", lambda m: m != "torch" and real(m))
    with pytest.raises(SweepError) as err:
        validate("rotorpy", 10)
    msg = str(err.value)
    assert "'rotorpy'" in msg and "[batched]" in msg and "pip install" in msg and "\n" not in msg
    validate("group", 10)  # a family without RotorPy needs no torch
    monkeypatch.undo()
    validate("rotorpy", 10)
