"""Scenarios made by a rule, in one place: swarms of any size (a constant-density random
crossing, an antipodal swap on a sphere) and the sweep families of random encounters.

Importing this package registers every family (:mod:`.families`), so ``FAMILIES`` and
``make_encounter`` see them all."""

from vo3d_opt.generators import families  # noqa: F401 - registers the families
from vo3d_opt.generators.encounter import (
    DT,
    FAMILIES,
    PRISM_CLEARANCE,
    SEPARATION,
    TIME_FACTOR,
    TIME_SLACK,
    Draw,
    Family,
    SweepEncounter,
    encounter_name,
    encounter_problems,
    encounter_rng,
    get_family,
    make_encounter,
    register,
    schema_has,
)
from vo3d_opt.generators.swarms import (
    RVO2_SPHERE,
    fibonacci_sphere,
    random_crossing_scenario,
    rvo2_sphere_scenario,
    sphere_swap_scenario,
)

__all__ = [
    "DT",
    "Draw",
    "FAMILIES",
    "Family",
    "PRISM_CLEARANCE",
    "SEPARATION",
    "SweepEncounter",
    "TIME_FACTOR",
    "TIME_SLACK",
    "encounter_name",
    "encounter_problems",
    "encounter_rng",
    "fibonacci_sphere",
    "get_family",
    "make_encounter",
    "RVO2_SPHERE",
    "random_crossing_scenario",
    "rvo2_sphere_scenario",
    "register",
    "schema_has",
    "sphere_swap_scenario",
]
