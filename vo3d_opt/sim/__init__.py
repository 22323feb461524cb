"""Scenario files, the decentralised multi-UAV simulator and its safety metrics.

Layering: this package uses ``vo3d_opt.types`` and (lazily) ``vo3d_opt.selector``; nothing
below it imports it. What a run writes to disk: ``vo3d_opt.report``.
"""

from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import Scenario, ScenarioError, load_scenario, scenario_from_dict
from vo3d_opt.sim.simulator import RunRecord, Simulator, fly, run_scenario

__all__ = [
    "RunRecord",
    "Scenario",
    "ScenarioError",
    "Simulator",
    "load_scenario",
    "run_scenario",
    "scenario_from_dict",
    "fly",
    "summarize",
]
