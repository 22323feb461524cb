"""With noisy or late sensing, every vehicle decided in one compiled call
(``vo3d_opt.sim.sensed_batch``) flies exactly as a ``select`` call per vehicle does."""
from __future__ import annotations

import pytest
import yaml
from test_lockstep import same_record

from vo3d_opt.sim.deciders import PerAgentSelect, decision_step
from vo3d_opt.sim.scenario import scenario_from_dict
from vo3d_opt.sim.scenario.loader import bundled_dir
from vo3d_opt.sim.simulator import fly, scenario_selector
from vo3d_opt.sweep import Method, make_encounter
from vo3d_opt.sweep.flight import flown


def both_ways(make):
    """The run with the vehicles decided in one call, and with a select() each."""
    records = []
    for one_call in (True, False):
        sc, step = make()
        assert isinstance(step, PerAgentSelect) and step.one_call
        step.one_call = one_call
        records.append(fly(sc, step, progress=False))
    return records


@pytest.mark.parametrize("index", range(3))
def test_noisy_encounters_fly_as_with_a_select_per_vehicle(index):
    got, want = both_ways(lambda: flown(make_encounter("noisy", 3, index).load(), Method())[:2])
    assert got.steps > 10 and same_record(want, got)


@pytest.mark.parametrize("name", ["paper-case3-three-spheres", "intruder-crossing-four"])
def test_spheres_obstacles_latency_and_traffic_that_does_not_avoid(name):
    """Spheres and obstacles (case 3), a vehicle that does not avoid (the intruder) and
    arrivals, each sensed as not avoiding, under noise and a latency of two steps."""
    data = yaml.safe_load((bundled_dir() / f"{name}.yaml").read_text())
    data["sensing"] = {**data.get("sensing", {}), "position_noise": 0.4, "velocity_noise": 0.2,
                       "latency": 2 * data["dt"], "seed": 5}

    def make():
        sc = scenario_from_dict(data)
        selector, formulation, solver = scenario_selector(sc)
        return sc, decision_step(sc, selector, formulation=formulation, solver=solver)

    got, want = both_ways(make)
    assert same_record(want, got)
