"""Batched RotorPy vehicles of many runs in one fleet (vo3d_opt.sim.rotorpy_fleet): each run's
numbers are those of the run flown alone, bit for bit, and no run waits for one that is over."""

import threading

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("rotorpy")

from vo3d_opt.sim.dynamics import make_dynamics  # noqa: E402
from vo3d_opt.sim.metrics import summarize  # noqa: E402
from vo3d_opt.sim.record import StepDecision  # noqa: E402
from vo3d_opt.sim.rotorpy_fleet import RotorPyFleet  # noqa: E402
from vo3d_opt.sim.scenario import scenario_from_dict  # noqa: E402
from vo3d_opt.sim.simulator import fly  # noqa: E402
from vo3d_opt.sweep import flight  # noqa: E402

BATCHED = {"model": "rotorpy", "batched": True}
WINDS = [None, {"type": "constant", "velocity": [2.0, 0.0, 0.0]},
         {"type": "dryden", "velocity": [1.0, 1.0, 0.0]}]


def _case(j: int, periods: int) -> dict:
    """Run j: 2 + j vehicles, its own wind, seed, commands and length; vehicle 0 held from
    period 2 to 5 (hold and release inside the fleet)."""
    rng = np.random.default_rng(j)
    n = 2 + j
    return {"n": n, "wind": WINDS[j % 3], "seed": j, "starts": rng.normal(size=(n, 3)) * 5,
            "commands": rng.uniform(-3, 3, size=(periods, n, 3))}


def _flown(case: dict, dyn) -> list[np.ndarray]:
    dyn.reset(case["starts"])
    out = []
    hold = np.arange(case["n"]) == 0
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

    threads = [threading.Thread(target=one, args=(i,)) for i in range(len(cases))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "a run waits for ever"
    assert not errors, errors
    return out


def test_runs_in_a_fleet_fly_as_each_alone_bit_for_bit():
    # runs of different lengths (the short ones leave while the others fly), winds, seeds
    cases = [_case(j, periods) for j, periods in enumerate((7, 3, 8, 1, 6))]
    alone = [_flown(c, make_dynamics(BATCHED, c["wind"], seed=c["seed"])) for c in cases]
    together = _in_threads(cases, RotorPyFleet())
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
        except ValueError as exc:
            errors.append(str(exc))
        finally:
            models[i].leave()

    threads = [threading.Thread(target=one, args=(i, dt)) for i, dt in enumerate((0.2, 0.1))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert not any(t.is_alive() for t in threads)
    assert len(errors) == 2 and all(e.startswith("dt:") for e in errors)


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


def test_a_sweep_task_flies_its_encounters_in_a_fleet_with_the_rows_of_each_alone():
    waiting = []
    for j in range(3):
        sc = scenario_from_dict({k: v for k, v in _scenario(j).items() if v is not None})
        assert flight.in_fleet(sc)
        sc, step, options = flight.flown(sc, flight.Method())
        if j == 1:
            step = _Failing(step)
        waiting.append(flight._Waiting({"index": j, "error": None}, sc, step, options, 0.0))
    flight._fly_in_fleet(waiting)
    assert "decision failed on purpose" in waiting[1].row["error"]
    for j in (0, 2):
        w = waiting[j]
        assert w.row["error"] is None
        alone = fly(w.sc, flight.flown(w.sc, flight.Method())[1], progress=False)
        expected = {"index": j, "error": None}
        flight._summarised(expected, alone, {**summarize(alone), "selector_options": w.options})
        same = [k for k in expected if k not in flight.TIMING_COLUMNS]
        assert len(same) > 10
        assert {k: w.row[k] for k in same} == {k: expected[k] for k in same}
