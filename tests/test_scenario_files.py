"""Scenario files: every bundled file loads, names are unique, and invalid files
are rejected with one line naming the file and the key."""
from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
import yaml

from vo3d_opt.sim.scenario import (
    Scenario,
    ScenarioError,
    bundled_dir,
    bundled_files,
    load_scenario,
    resolve,
    scenario_from_dict,
    scenario_variant,
)
from vo3d_opt.generators import random_crossing_scenario
from vo3d_opt.sim.simulator import run_scenario
from vo3d_opt.types import Box, Cylinder

BASE: dict[str, Any] = {
    "name": "unit-base",
    "description": "A valid scenario. Mutated by the tests.",
    "dt": 0.2,
    "max_time": 20.0,
    "goal_tolerance": 1.0,
    "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
    "sensing": {"vehicle_range": 55.0, "obstacle_range": 55.0},
    "defaults": {"r_pz": 10.0, "radius": 0.5, "max_speed": 4.0},
    "agents": [
        {"id": "u0", "start": [40.0, 0.0, 20.0], "goal": [-40.0, 0.0, 20.0]},
        {"id": "u1", "start": [-40.0, 0.0, 20.0], "goal": [40.0, 0.0, 20.0], "r_pz": 8.0},
        {"id": "u2", "start": [0.0, 40.0, 10.0], "goal": [0.0, -40.0, 30.0]},
    ],
    "obstacles": [
        {"type": "cylinder", "center": [0.0, 10.0], "radius": 3.0, "height": 30.0},
        {"type": "box", "center": [10.0, -10.0], "size": [6.0, 6.0], "height": 25.0, "yaw": 0.3},
    ],
}

PAPER_FILES = [
    "paper-case1-ten-uav-crossing",
    "paper-case2-two-uav-six-obstacles",
    "paper-case3-two-uav-two-cylinders",
    "paper-case3-three-spheres",
    "paper-case4-five-uav-six-square-obstacles",
    "paper-flight-test",
]


def write(tmp_path: Path, data: Any, name: str = "scenario.yaml") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
    return path


def mutated(fn: Callable[[dict], None]) -> dict:
    data = copy.deepcopy(BASE)
    fn(data)
    return data


def _set(path: str, value: Any) -> Callable[[dict], None]:
    """A mutation setting a dotted key path (list indices as numbers)."""

    def fn(d: dict) -> None:
        keys = path.split(".")
        for k in keys[:-1]:
            d = d[int(k)] if k.isdigit() else d[k]
        last = keys[-1]
        if last.isdigit():
            d[int(last)] = value
        else:
            d[last] = value

    return fn


def _del(path: str) -> Callable[[dict], None]:
    def fn(d: dict) -> None:
        keys = path.split(".")
        for k in keys[:-1]:
            d = d[int(k)] if k.isdigit() else d[k]
        del d[keys[-1]]

    return fn


# (mutation, key path the message must name, a fragment of the problem)
MISTAKES = [
    pytest.param(_set("spead", 3), "spead", "unknown key", id="unknown-top-level-key"),
    pytest.param(_set("agents.0.r_pzz", 3.0), "agents[0].r_pzz", "did you mean 'r_pz'",
                 id="unknown-agent-key"),
    pytest.param(_set("obstacles.1.colour", "red"), "obstacles[1].colour", "unknown key",
                 id="unknown-obstacle-key"),
    pytest.param(_del("dt"), "dt", "missing", id="missing-dt"),
    pytest.param(_del("name"), "name", "missing", id="missing-name"),
    pytest.param(_del("agents.2.goal"), "agents[2].goal", "missing", id="missing-goal"),
    pytest.param(_del("obstacles.0.type"), "obstacles[0].type", "missing", id="missing-type"),
    pytest.param(_set("dt", "fast"), "dt", "number", id="string-for-number"),
    pytest.param(_set("dt", True), "dt", "number", id="bool-for-number"),
    pytest.param(_set("max_time", "20"), "max_time", "number", id="quoted-number"),
    pytest.param(_set("agents.0.id", 7), "agents[0].id", "string", id="number-for-id"),
    pytest.param(_set("agents", {"u0": 1}), "agents", "list", id="mapping-for-list"),
    pytest.param(_set("agents.1.start", [1.0, 2.0]), "agents[1].start", "3 numbers",
                 id="short-vector"),
    pytest.param(_set("agents.1.start", [1.0, "a", 2.0]), "agents[1].start", "3 numbers",
                 id="string-in-vector"),
    pytest.param(_set("agents.1.start", [float("nan"), 0.0, 20.0]), "agents[1].start", "finite",
                 id="nan-in-vector"),
    pytest.param(_set("max_time", float("inf")), "max_time", "finite", id="infinite-max-time"),
    pytest.param(_set("defaults.radius", float("nan")), "defaults.radius", "finite", id="nan-radius"),
    pytest.param(_set("dt", -0.2), "dt", "greater than 0", id="negative-dt"),
    pytest.param(_set("dt", 0), "dt", "greater than 0", id="zero-dt"),
    pytest.param(_set("max_time", 0.0), "max_time", "greater than 0", id="zero-max-time"),
    pytest.param(_set("max_time", 0.1), "max_time", "shorter than one step", id="max-time-below-dt"),
    pytest.param(_set("goal_tolerance", 0.0), "goal_tolerance", "greater than 0",
                 id="zero-goal-tolerance"),
    pytest.param(_set("defaults.r_pz", -10.0), "defaults.r_pz", "greater than 0",
                 id="negative-default-r_pz"),
    pytest.param(_set("agents.1.radius", 0.0), "agents[1].radius", "greater than 0",
                 id="zero-agent-radius"),
    pytest.param(_set("agents.2.max_speed", -1.0), "agents[2].max_speed", "greater than 0",
                 id="negative-max-speed"),
    pytest.param(_set("obstacles.0.radius", -3.0), "obstacles[0].radius", "greater than 0",
                 id="negative-obstacle-radius"),
    pytest.param(_set("obstacles.1.size", [6.0, 0.0]), "obstacles[1].size", "positive",
                 id="zero-box-side"),
    pytest.param(_set("obstacles.1.height", 0.0), "obstacles[1].height", "greater than 0",
                 id="zero-box-height"),
    pytest.param(_set("sensing.vehicle_range", 0.0), "sensing.vehicle_range", "greater than 0",
                 id="zero-vehicle-range"),
    pytest.param(_set("sensing.obstacle_range", -5.0), "sensing.obstacle_range", "greater than 0",
                 id="negative-obstacle-range"),
    pytest.param(_set("limits.speed", [4.0, 1.0]), "limits.speed", "empty range",
                 id="empty-speed-range"),
    pytest.param(_set("limits.speed", [-1.0, 4.0]), "limits.speed", "negative",
                 id="negative-min-speed"),
    pytest.param(_set("limits.altitude", [40.0, 0.0]), "limits.altitude", "empty range",
                 id="empty-altitude-range"),
    pytest.param(_set("limits.altitude", [10.0, 10.0]), "limits.altitude", "empty range",
                 id="zero-altitude-range"),
    pytest.param(_set("agents.2.start", [0.0, 40.0, -1.0]), "agents[2].start",
                 "below the altitude floor 0", id="start-below-floor"),
    pytest.param(_set("agents.0.goal", [-40.0, 0.0, 45.0]), "agents[0].goal",
                 "above the altitude ceiling 40", id="goal-above-ceiling"),
    pytest.param(_set("agents.1.start", [0.0, 10.0, 5.0]), "agents[1].start", "inside obstacles[0]",
                 id="start-inside-cylinder"),
    pytest.param(_set("agents.2.start", [10.0, -10.0, 24.0]), "agents[2].start",
                 "inside obstacles[1]", id="start-inside-box"),
    pytest.param(_set("agents.0.goal", [2.8, 10.0, 20.0]), "agents[0].goal", "inside obstacles[0]",
                 id="goal-inside-cylinder"),
    pytest.param(_set("agents.2.id", "u0"), "agents[2].id", "duplicate id 'u0'", id="duplicate-id"),
    pytest.param(_set("agents.1.start", [40.2, 0.0, 20.0]), "agents[1].start", "overlaps agents[0]",
                 id="overlapping-starts"),
    pytest.param(_set("obstacles.0.type", "cone"), "obstacles[0].type", "unknown obstacle type",
                 id="unknown-obstacle-type"),
    pytest.param(_set("obstacles.0.h_pz", 20.0), "obstacles[0].h_pz", "below the obstacle height",
                 id="prism-lower-than-obstacle"),
    pytest.param(_set("obstacles.1.L_pz", 5.0), "obstacles[1].L_pz", "largest extent",
                 id="prism-narrower-than-box"),
    pytest.param(_set("agents", []), "agents", "at least 1", id="no-agents"),
    pytest.param(lambda d: (d["limits"].update(speed=[1.0, 4.0]),
                            d["agents"][2].update(max_speed=0.5)),
                 "agents[2].max_speed", "below the minimum speed", id="max-speed-below-min-speed"),
    pytest.param(_set("spheres", [{"center": [0.0, -30.0, 20.0], "radius": 0.0}]), "spheres[0].radius",
                 "greater than 0", id="zero-sphere-radius"),
    pytest.param(_set("velocity_response_tau", 0.0), "velocity_response_tau", "greater than 0",
                 id="zero-tau"),
    pytest.param(_set("selector_options", {"speed_levels": 2.5}), "selector_options.speed_levels",
                 "integer", id="fractional-selector-option"),
    pytest.param(_set("selector_options", {"corrections": ["bogus"]}), "selector_options.corrections[0]",
                 "tg_range", id="unknown-correction"),
    pytest.param(_set("selector_options", {"colour": 1}), "selector_options.colour", "unknown key",
                 id="unknown-selector-option"),
    pytest.param(_set("selector_options", {"horizon": "fast"}), "selector_options.horizon",
                 "null or 'sensing', got 'fast'", id="horizon-text"),
    pytest.param(_set("solver", "nosuch"), "solver", "available", id="unknown-solver"),
    pytest.param(_set("formulation", "magic"), "formulation", "plane_qp", id="unknown-formulation"),
    pytest.param(_set("selector_options", {"formulation": "sampled"}), "selector_options.formulation",
                 "'formulation' belongs at the top level", id="top-level-key-as-selector-option"),
    pytest.param(_set("limits.r_pz", 5.0), "limits.r_pz", "belongs in defaults and in agents[]",
                 id="agent-key-in-limits"),
    pytest.param(_set("obstacles.0.radius", True), "obstacles[0].radius", "must be a number",
                 id="bool-for-obstacle-radius"),
    pytest.param(_set("limits.speed", ["0", "4"]), "limits.speed", "2 numbers",
                 id="strings-for-speed-range"),
    pytest.param(_set("dt", 20.0), "dt", "sensing.vehicle_range 55 m", id="step-beyond-sensing"),
    pytest.param(lambda d: (d.update(dt=5.0), d["sensing"].update(obstacle_range=15.0)), "dt",
                 "sensing.obstacle_range 15 m", id="step-beyond-obstacle-sensing"),
]


@pytest.mark.parametrize("mutation, key, fragment", MISTAKES)
def test_invalid_file_is_rejected_naming_file_and_key(tmp_path, mutation, key, fragment):
    path = write(tmp_path, mutated(mutation))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert msg.startswith(f"{path}: {key}:"), msg
    assert fragment in msg, msg
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize(
    "text, fragment",
    [
        pytest.param("name: a\nname: b\n", "duplicate key 'name'", id="duplicate-yaml-key"),
        pytest.param("name: [unclosed\n", "invalid YAML", id="yaml-syntax"),
        pytest.param("- just\n- a list\n", "must be a YAML mapping", id="not-a-mapping"),
        pytest.param("", "must be a YAML mapping", id="empty-file"),
    ],
)
def test_unparsable_file_is_rejected_on_one_line(tmp_path, text, fragment):
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path)) and fragment in msg, msg


def test_missing_file_names_the_file(tmp_path):
    path = tmp_path / "nope.yaml"
    with pytest.raises(ScenarioError, match=r"nope\.yaml: cannot read"):
        load_scenario(path)


def test_several_problems_are_all_shown_on_one_line(tmp_path):
    data = mutated(lambda d: (d.update(dt=-1.0), d["defaults"].update(r_pz=-1.0),
                              d["agents"][1].update(colour="red")))
    path = write(tmp_path, data)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg and "more problem" not in msg, msg
    assert msg == (f"{path}: dt: input should be greater than 0; defaults.r_pz: input should be "
                   f"greater than 0; agents[1].colour: unknown key"), msg


def test_several_cross_field_problems_are_all_shown(tmp_path):
    data = mutated(lambda d: (d["agents"][0].update(goal=[-40.0, 0.0, 50.0]),
                              d["agents"][2].update(id="u0")))
    with pytest.raises(ScenarioError) as info:
        load_scenario(write(tmp_path, data))
    msg = str(info.value)
    assert "agents[0].goal: above the altitude ceiling" in msg, msg
    assert "agents[2].id: duplicate id 'u0'" in msg, msg


def test_valid_base_loads_into_types(tmp_path):
    sc = load_scenario(write(tmp_path, BASE))
    assert isinstance(sc, Scenario) and sc.source.endswith("scenario.yaml")
    assert sc.n_agents == 3 and sc.ids == ["u0", "u1", "u2"]
    assert isinstance(sc.bodies[0], Cylinder) and isinstance(sc.bodies[1], Box)
    assert sc.bodies[1].yaw == pytest.approx(0.3)
    np.testing.assert_allclose(sc.r_pz, [10.0, 8.0, 10.0])  # per-agent override
    np.testing.assert_allclose(sc.radius, [0.5, 0.5, 0.5])
    assert sc.n_steps == 100
    lim = sc.agent_limits(0)
    assert lim.speed == (0.0, 4.0) and lim.altitude == (0.0, 40.0)
    assert sc.start_warnings() == []


def test_optional_keys_and_overrides():
    data = mutated(lambda d: d.update(
        velocity_response_tau=0.5, formulation="sampled", solver="osqp",
        selector_options={"plane_step_deg": 15.0},
        spheres=[{"center": [0.0, -30.0, 20.0], "radius": 2.0, "margin": 1.0, "physical": False}],
    ))
    data["agents"][2]["max_speed"] = 6.0  # above limits.speed[1]: the limit wins
    data["agents"][1]["max_speed"] = 2.5
    data["obstacles"][0].update(L_pz=9.0, h_pz=33.0, sensed=False)
    sc = scenario_from_dict(data)
    np.testing.assert_allclose(sc.max_speed, [4.0, 2.5, 4.0])
    assert sc.agent_limits(1).speed == (0.0, 2.5)
    assert sc.bodies[0].side == 9.0 and sc.bodies[0].prism_height == 33.0
    assert sc.bodies[1].side == pytest.approx(np.hypot(6, 6) + 4.0)  # derived with the margin
    assert list(sc.sensed) == [False, True]
    (sphere,) = sc.sphere_neighbors()
    assert sphere.r_pz == 3.0 and not np.any(sphere.velocity)
    assert sc.velocity_response_tau == 0.5 and sc.formulation == "sampled"


def test_start_inside_protected_zone_is_allowed_but_reported():
    # u1 1 m from the cylinder's surface: outside the obstacle, inside its protected prism;
    # u0 and u2 8 m apart: inside each other's protected zone (10 m).
    data = mutated(lambda d: d["agents"][1].update(start=[0.0, 6.0, 20.0]))
    data["agents"][0]["start"] = [-40.0, 5.0, 20.0]
    data["agents"][2]["start"] = [-40.0, -3.0, 20.0]
    sc = scenario_from_dict(data)
    warnings = sc.start_warnings()
    assert any("protected prism of obstacles[0]" in w for w in warnings)
    assert any("u0 and u2" in w for w in warnings)


def test_starting_at_the_goal_and_ints_are_fine():
    data = mutated(lambda d: d.update(dt=1, max_time=10))
    data["agents"][2]["goal"] = [0, 40, 10]  # already at its goal
    sc = scenario_from_dict(data)
    assert sc.dt == 1.0 and sc.n_steps == 10


def test_exponent_without_dot_is_a_number(tmp_path):
    """YAML 1.1 reads 1e9 as a string; the loader reads YAML 1.2 floats."""
    text = yaml.safe_dump(mutated(lambda d: d.update(max_time=20.0)), sort_keys=False)
    text = text.replace("max_time: 20.0", "max_time: 1e5").replace("dt: 0.2", "dt: 2E-1")
    sc = load_scenario(write(tmp_path, text))
    assert sc.max_time == 1e5 and sc.dt == 0.2
    quoted = text.replace("max_time: 1e5", "max_time: '1e5'")
    with pytest.raises(ScenarioError, match="max_time: must be a number, got '1e5'"):
        load_scenario(write(tmp_path, quoted))
    assert yaml.safe_load("x: 1e9") == {"x": "1e9"}  # PyYAML's own loader is left as it was


def test_step_longer_than_a_protected_zone_is_reported():
    sc = scenario_from_dict(mutated(lambda d: d.update(dt=3.0)))  # 12 m per step, r_pz 8 / 10
    assert sc.start_warnings() == []
    warnings = sc.warnings()
    assert len(warnings) == 3 and all("12 m per step" in w for w in warnings), warnings
    assert scenario_from_dict(BASE).warnings() == []


def test_a_swarm_under_rotorpy_one_by_one_is_pointed_to_the_batched_model():
    crossing = load_scenario("random-crossing-50")
    one_by_one = scenario_variant(crossing, dynamics={"model": "rotorpy"})
    assert any("dynamics.batched: true" in w for w in one_by_one.warnings())
    batched = scenario_variant(crossing, dynamics={"model": "rotorpy", "batched": True})
    assert crossing.warnings() == batched.warnings() == []
    few = scenario_variant(load_scenario("paper-case1-ten-uav-crossing"),
                           dynamics={"model": "rotorpy"})
    assert few.warnings() == []
    # from BATCHED_ADVISED = 50 vehicles on
    for n, warned in ((49, False), (50, True)):
        swarm = scenario_variant(random_crossing_scenario(n, seed=1), dynamics={"model": "rotorpy"})
        assert any("batched" in w for w in swarm.warnings()) == warned


def test_load_scenario_warns_through_logging(tmp_path, caplog):
    path = write(tmp_path, mutated(lambda d: d.update(dt=3.0)))
    with caplog.at_level("WARNING", logger="vo3d_opt"):
        load_scenario(path)
    assert sum("more than its protected-zone radius" in r.getMessage() for r in caplog.records) == 3


def test_bundled_name_loads_and_a_near_miss_suggests_names():
    assert load_scenario("sphere-swap-16").source == str(bundled_dir() / "sphere-swap-16.yaml")
    with pytest.raises(ScenarioError) as info:
        load_scenario("paper-case1")
    msg = str(info.value)
    assert msg.startswith("paper-case1: no such file or bundled scenario"), msg
    assert "paper-case1-ten-uav-crossing" in msg and "vo3d list" in msg and "\n" not in msg, msg
    assert "sphere-swap-16" in str(pytest.raises(ScenarioError, load_scenario, "sphere-swop-16").value)


def test_run_scenario_accepts_bundled_names():
    rec = run_scenario("paper-flight-test", max_steps=3, progress=False)
    assert rec.scenario.name == "paper-flight-test" and rec.steps == 3


# ------------------------------------------------------------------------------------ bundled


def test_bundled_directory_has_the_paper_cases_and_ours():
    stems = {p.stem for p in bundled_files()}
    assert set(PAPER_FILES) <= stems, set(PAPER_FILES) - stems
    assert len(stems - set(PAPER_FILES)) >= 5


@pytest.mark.parametrize("path", bundled_files(), ids=lambda p: p.stem)
def test_every_bundled_file_loads(path):
    sc = load_scenario(path)
    assert sc.name == path.stem, "the file is named after its scenario"
    assert sc.description.strip(), "every bundled scenario says what it is"
    if sc.name == "rvo2-sphere-812":  # RVO2-3D's own example, as its authors wrote it
        assert len(sc.warnings()) == 3 and all("start" in w for w in sc.warnings())
    else:
        assert sc.warnings() == [], "bundled scenarios start outside every protected zone"
    assert resolve(sc.name) == path


def test_bundled_names_are_unique():
    names = [load_scenario(p).name for p in bundled_files()]
    assert len(names) == len(set(names)), sorted(names)


def test_paper_parameters_follow_table_1():
    for stem in PAPER_FILES:
        if stem == "paper-flight-test":
            continue
        sc = load_scenario(bundled_dir() / f"{stem}.yaml")
        assert sc.sensing.vehicle_range == 55.0 and sc.sensing.obstacle_range == 55.0
        assert sc.limits.speed == (0.0, 4.0) and sc.limits.altitude == (0.0, 40.0)
        assert np.all(sc.r_pz == 10.0) and sc.dt == 0.2


def test_flight_test_fits_the_room():
    sc = load_scenario(bundled_dir() / "paper-flight-test.yaml")
    assert sc.n_agents == 1 and len(sc.obstacles) == 1 and sc.dt == 0.2  # 5 Hz
    assert sc.limits.altitude[1] <= 1.0  # the maximum height of section 6
    pts = np.concatenate([sc.starts, sc.goals])
    assert np.all((pts[:, :2] >= 0.0) & (pts[:, :2] <= 6.0))
