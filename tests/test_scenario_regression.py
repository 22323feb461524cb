"""Regression over the bundled scenarios: every one under the default formulation (plane_qp),
with the closing guard (the simulator's default) and without it, and the paper's cases also under the paper's sampled
selection, must end with every agent
arrived, no collision, no protected-zone intrusion and no speed or altitude violation. The
swarm-sized scenarios are flown by benchmarks/bench_swarm.py instead (a test flies the first
steps of each: tests/test_sim_loop.py)."""
from __future__ import annotations

import json

import pytest
import yaml

from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import bundled_files, scenario_from_dict
from vo3d_opt.sim.simulator import run_scenario


#: Bundled scenarios too large for the suite's time budget.
SWARMS = {"random-crossing-1000", "rvo2-sphere-812"}
FILES = [p for p in bundled_files() if p.stem not in SWARMS]
PAPER = [p for p in FILES if p.stem.startswith("paper-")]
CASES = [pytest.param(p, "plane_qp", id=f"{p.stem}-plane_qp") for p in FILES] + [
    pytest.param(p, "sampled", id=f"{p.stem}-sampled") for p in PAPER
] + [pytest.param(p, "plane_qp+no_guard", id=f"{p.stem}-no_guard") for p in FILES]


def _scenario(path, formulation):
    """The file, or with ``+no_guard`` its data with the guard turned off in its options."""
    if not formulation.endswith("+no_guard"):
        return path
    data = yaml.safe_load(path.read_text())
    data["selector_options"] = {**data.get("selector_options", {}), "closing_guard": False}
    return scenario_from_dict(data, str(path))


def test_there_is_something_to_check():
    assert len(FILES) >= 11 and len(PAPER) == 6


@pytest.mark.parametrize("path, formulation", CASES)
def test_bundled_scenario_is_safe(path, formulation):
    record = run_scenario(_scenario(path, formulation), formulation=formulation.split("+")[0],
                          progress=False)
    s = summarize(record)
    problems = []
    if not s["all_reached"]:
        problems.append(f"{s['agents'] - s['reached']} of {s['agents']} agents did not arrive "
                        f"within {record.scenario.max_time:g} s")
    for key in ("collisions", "pz_intrusions", "altitude_violations", "speed_violations"):
        if s[key]:
            problems.append(f"{key} = {s[key]}")
    brief = {k: s[k] for k in ("steps", "min_vehicle_distance", "min_obstacle_distance",
                               "fallbacks", "status_counts", "decision_time_median_us",
                               "wall_time")}
    assert not problems, (f"{s['scenario']} under {formulation}/{s['solver']}: "
                          + "; ".join(problems) + f"  {json.dumps(brief)}")
