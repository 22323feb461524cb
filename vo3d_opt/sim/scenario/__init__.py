"""Scenario files: the schema (:mod:`.schema`, pydantic models built on the public
types of ``vo3d_opt.types``) and the loader (:mod:`.loader`: YAML, bundled names, one-line
errors). The format is documented in :mod:`.schema`, what is rejected in :mod:`.loader`."""

from vo3d_opt.sim.scenario.loader import (
    ScenarioError,
    bundled_dir,
    bundled_files,
    check_selector_options,
    close_names,
    load_scenario,
    parse_option,
    resolve,
    scenario_from_dict,
    scenario_variant,
)
from vo3d_opt.sim.scenario.schema import (
    AgentSpec,
    BoxSpec,
    CylinderSpec,
    DefaultsSpec,
    Scenario,
    SensingSpec,
    SphereSpec,
    prism_contains,
    sphere_surface_distance,
)

__all__ = [
    "AgentSpec",
    "BoxSpec",
    "CylinderSpec",
    "DefaultsSpec",
    "Scenario",
    "ScenarioError",
    "SensingSpec",
    "SphereSpec",
    "bundled_dir",
    "bundled_files",
    "check_selector_options",
    "close_names",
    "load_scenario",
    "parse_option",
    "prism_contains",
    "resolve",
    "scenario_from_dict",
    "scenario_variant",
    "sphere_surface_distance",
]
