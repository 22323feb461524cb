"""Encounters flown side by side (``vo3d_opt.sim.lockstep``) fly exactly as ``fly`` flies each
alone, and the sweep's batched rows are its single rows."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from vo3d_opt.sim import metrics
from vo3d_opt.sim.lockstep import fits, fly_together
from vo3d_opt.sim.simulator import fly
from vo3d_opt.sweep import Method, make_encounter, run_encounter
from vo3d_opt.sweep.flight import flown, run_encounters
from vo3d_opt.sweep.runner import rows_equal

TIMING = ("decision_time_median_us", "decision_time_p99_us", "decision_time_max_us", "wall_time")


def same_record(a, b) -> bool:
    return (
        a.steps == b.steps
        and a.same_trajectory(b)
        and np.array_equal(a.preferred, b.preferred)
        and np.array_equal(a.decided, b.decided)
        and a.status_names == b.status_names
        and np.array_equal(a.status_codes, b.status_codes)
        and a.extra == b.extra
    )


def summary(record) -> dict:
    return {k: v for k, v in metrics.summarize(record).items() if k not in TIMING}


@pytest.mark.parametrize(("family", "count", "method"), [
    ("pair", 12, "vo3d"), ("group", 6, "vo3d"), ("lagged", 6, "vo3d"),
    ("intruder", 6, "vo3d"), ("dense", 3, "vo3d"), ("group", 6, "none"), ("noisy", 6, "vo3d"),
])
def test_flown_together_as_each_alone(family, count, method):
    runs = [flown(make_encounter(family, 7, i).load(), Method(name=method))[:2]
            for i in range(count)]
    assert all(fits(sc, step) for sc, step in runs)
    together = fly_together(runs)
    for (sc, _), got in zip(runs, together, strict=True):
        sc2, step2, _ = flown(make_encounter(family, 7, int(sc.name.rsplit("i", 1)[1])).load(),
                              Method(name=method))
        alone = fly(sc2, step2, progress=False)
        assert same_record(alone, got), sc.name
        assert summary(alone) == summary(got), sc.name


def test_a_landing_and_a_first_order_run_side_by_side_with_others():
    """dense 3502 lands an agent at its goal's door (sim/landing.py); lagged flies first-order
    dynamics: with two plain pair encounters in the same batch each is still its own run."""
    from pathlib import Path

    from vo3d_opt.sim.scenario import load_scenario

    data = Path(__file__).parent / "data" / "sweep-failures"
    scs = [load_scenario(data / "dense-s0-i3502.yaml"), load_scenario(data / "lagged-s0-i413.yaml"),
           make_encounter("pair", 1, 0).load(), make_encounter("pair", 1, 1).load()]
    runs = [flown(sc, Method())[:2] for sc in scs]
    together = fly_together(runs)
    assert together[0].extra["landings"] > 0
    for sc, got in zip(scs, together, strict=True):
        alone = fly(*flown(sc, Method())[:2], progress=False)
        assert same_record(alone, got), sc.name


def test_arrived_agents_keeping_watch_side_by_side_with_others():
    """intruder 29918: an arrived vehicle decides again while the intruder is in range
    (traffic.keep_watch); side by side with another intruder run and two pair runs, each
    vehicle still sees only its own run's."""
    from pathlib import Path

    from vo3d_opt.sim.scenario import load_scenario

    data = Path(__file__).parent / "data" / "sweep-failures"
    scs = [load_scenario(data / "intruder-s0-i29918.yaml"), make_encounter("pair", 1, 0).load(),
           load_scenario(data / "intruder-s0-i63083.yaml"), make_encounter("pair", 1, 1).load()]
    runs = [flown(sc, Method())[:2] for sc in scs]
    together = fly_together(runs)
    watched = together[0].decided & together[0].arrived[:-1]
    assert watched.any()
    for sc, got in zip(scs, together, strict=True):
        alone = fly(*flown(sc, Method())[:2], progress=False)
        assert same_record(alone, got), sc.name


def test_arrived_agents_making_room_for_a_stuck_one_side_by_side_with_others():
    """dense 95048: vehicles hovering at their goals decide again while an agent on a detour
    from a stall is in range (``GoalWithDetours.stuck``); side by side with two pair runs, each
    run is still its own, and the batch's detour rule wakes only the stuck run's vehicles."""
    from pathlib import Path

    from encounters import PAPER_GRID
    from vo3d_opt.sim.scenario import load_scenario, scenario_variant

    data = Path(__file__).parent / "data" / "sweep-failures"
    stuck = load_scenario(data / "dense-s0-i95048.yaml")  # stalls on the planes it was found on
    stuck = scenario_variant(stuck, selector_options={**stuck.selector_options, **PAPER_GRID})
    scs = [make_encounter("pair", 1, 0).load(), stuck, make_encounter("pair", 1, 1).load()]
    together = fly_together([flown(sc, Method())[:2] for sc in scs])
    woken = together[1].decided & together[1].arrived[:-1]
    assert woken.any()
    for sc, got in zip(scs, together, strict=True):
        alone = fly(*flown(sc, Method())[:2], progress=False)
        assert same_record(alone, got), sc.name


@pytest.mark.parametrize("tau", [0.5, 1.0])
def test_a_watcher_back_home_stops_in_both_loops(tau):
    """``a`` keeps watch while ``b`` (avoids: false) passes and is still moving when it is back
    home: both loops stop it there, so ``c`` senses it hovering at the next step."""
    from vo3d_opt.sim.scenario import scenario_from_dict

    data = {"name": "watch", "dt": 0.2, "max_time": 40.0, "sensing": {"vehicle_range": 20.0},
            "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 20.0]},
            "defaults": {"r_pz": 5.0, "radius": 0.5, "max_speed": 4.0},
            "agents": [{"id": "a", "start": [0.0, 0.0, 10.0], "goal": [0.0, 0.0, 10.0]},
                       {"id": "b", "start": [30.0, 0.5, 10.0], "goal": [-30.0, 0.5, 10.0],
                        "avoids": False},
                       {"id": "c", "start": [-60.0, 8.0, 10.0], "goal": [60.0, 8.0, 10.0]}]}
    data["dynamics"] = {"model": "first_order", "tau": tau}  # still moving when home
    sc = scenario_from_dict(data, "watch.yaml")
    alone = fly(*flown(sc, Method())[:2], progress=False)
    watched = np.flatnonzero(alone.decided[:, 0])
    assert watched.size and np.abs(alone.velocities[watched[-1], 0]).max() > 0.01
    together = fly_together([flown(sc, Method())[:2], flown(make_encounter("pair", 1, 0).load(),
                                                             Method())[:2]])
    assert same_record(alone, together[0])


def test_runs_that_do_not_fit_are_refused():
    rotorpy = flown(make_encounter("rotorpy", 0, 0).load(), Method())
    assert not fits(rotorpy[0], rotorpy[1])
    with pytest.raises(ValueError, match="cannot be flown together"):
        fly_together([rotorpy[:2]])
    # runs that sense for themselves and runs that decide from the true snapshot: apart
    noisy = flown(make_encounter("noisy", 0, 0).load(), Method())
    pair = flown(make_encounter("pair", 0, 0).load(), Method())
    assert fits(noisy[0], noisy[1]) and fits(pair[0], pair[1])
    with pytest.raises(ValueError, match="batches of their own"):
        fly_together([noisy[:2], pair[:2]])


def test_noisy_runs_beside_a_run_without_avoidance():
    """A run in which nobody decides shares the batch of runs that sense for themselves: its
    vehicles are never decided for, and each run is still its own."""
    runs = [flown(make_encounter("noisy", 3, i).load(), Method())[:2] for i in (0, 1)]
    runs.insert(1, flown(make_encounter("pair", 3, 0).load(), Method(name="none"))[:2])
    together = fly_together(runs)
    for (sc, step), got in zip(runs, together, strict=True):
        family = "pair" if step.formulation == "none" else "noisy"
        name = Method(name="none") if family == "pair" else Method()
        index = int(sc.name.rsplit("i", 1)[1])
        sc2, step2, _ = flown(make_encounter(family, 3, index).load(), name)
        assert same_record(fly(sc2, step2, progress=False), got), sc.name


def test_noisy_runs_among_spheres_and_obstacles_side_by_side():
    """Noisy runs with spheres (the second with its spheres moved) and with prisms (two cases):
    each vehicle's spheres and obstacles are its own run's, wherever its run's rows start in
    the batch's tables."""
    from vo3d_opt.sim.scenario import (
        bundled_files,
        load_scenario,
        scenario_from_dict,
        scenario_variant,
    )

    files = {f.stem: f for f in bundled_files()}
    moved = load_scenario(files["paper-case3-three-spheres"]).model_dump(exclude_none=True)
    for sphere in moved["spheres"]:
        sphere["center"] = [sphere["center"][0] + 6.0, *sphere["center"][1:]]
    scenarios = [
        load_scenario(files["paper-case3-three-spheres"]),
        scenario_from_dict(moved, "<moved spheres>"),
        load_scenario(files["paper-case2-two-uav-six-obstacles"]),
        load_scenario(files["paper-case4-five-uav-six-square-obstacles"]),
    ]
    runs = []
    for seed, sc in enumerate(scenarios):
        sensing = {"vehicle_range": 55.0, "obstacle_range": 55.0, "position_noise": 0.4,
                   "velocity_noise": 0.2, "latency": 0.2, "seed": seed}
        runs.append(flown(scenario_variant(sc, sensing=sensing), Method())[:2])
    assert all(fits(sc, step) for sc, step in runs)
    together = fly_together(runs)
    for (sc, _), got in zip(runs, together, strict=True):
        alone = fly(*flown(sc, Method())[:2], progress=False)
        assert same_record(alone, got), sc.name


def test_a_batch_that_fails_late_is_flown_again_from_scratch(monkeypatch):
    """Should a batch raise after flying (its steps' sensors pushed, landings counted), each
    encounter is flown alone from a fresh step: the rows are still the single rows."""
    from vo3d_opt.sim import lockstep

    real = lockstep.fly_together

    def fails_at_the_end(runs):
        real(runs)
        raise RuntimeError("late")

    monkeypatch.setattr(lockstep, "fly_together", fails_at_the_end)
    indices = [4, 1, 3]
    alone = pd.DataFrame([run_encounter("noisy", 5, i) for i in indices])
    assert rows_equal(alone, pd.DataFrame(run_encounters("noisy", 5, indices)))


@pytest.mark.parametrize("family", ["pair", "noisy"])
@pytest.mark.parametrize("method", ["vo3d", "none"])
def test_batched_rows_are_the_single_rows(family, method):
    m = Method(name=method)
    indices = [3, 0, 5, 1, 2]
    alone = pd.DataFrame([run_encounter(family, 2, i, m) for i in indices])
    batched = pd.DataFrame(run_encounters(family, 2, indices, m))
    assert list(batched["index"]) == indices
    assert rows_equal(alone, batched)


def test_close_pairs_at_once_is_the_per_step_search(monkeypatch):
    rng = np.random.default_rng(3)
    for n, steps in [(2, 40), (5, 30), (12, 8), (3, 1)]:
        pos = np.cumsum(rng.normal(size=(steps, n, 3)), axis=0) * 3.0
        for threshold in (0.5, 4.0, 50.0):
            fast = metrics.close_pairs(pos, threshold)
            monkeypatch.setattr(metrics, "ALL_PAIRS_ELEMENTS", 0)
            slow = metrics.close_pairs(pos, threshold)
            monkeypatch.undo()
            for a, b in zip(fast, slow, strict=True):
                assert a.dtype == b.dtype and np.array_equal(a, b), (n, steps, threshold)
