"""``vo3d schema``: the published JSON Schema is the command's output, every bundled scenario
names it on its first line and validates against it, and it accepts what the loader accepts
(the sweep families' encounters, the recorded failures) and refuses what the loader refuses
for a single key (unknown keys, a wrong type, an unknown preset)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from vo3d_opt.cli import main
from vo3d_opt.cli.schema import PUBLISHED, schema_text
from vo3d_opt.generators import FAMILIES, make_encounter
from vo3d_opt.sim.scenario import ScenarioError, scenario_from_dict
from vo3d_opt.sim.scenario.reading import parse

jsonschema = pytest.importorskip("jsonschema", reason="jsonschema is in the dev extra")

ROOT = Path(__file__).resolve().parents[1]
SCHEMA_FILE = ROOT / "docs" / "reference" / "scenario.schema.json"
HEADER = f"# yaml-language-server: $schema={PUBLISHED}"
#: The repository's copies (an installed package carries them as package data).
SCENARIOS = sorted((ROOT / "scenarios").glob("*.yaml"))


@pytest.fixture(scope="module")
def validator() -> Any:
    schema = json.loads(SCHEMA_FILE.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _read(path: Path) -> dict[str, Any]:
    return parse(path.read_text())


def test_published_schema_is_the_command_output(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema"]) == 0
    printed = capsys.readouterr().out
    assert printed == schema_text()
    assert SCHEMA_FILE.read_text() == printed, (
        "docs/reference/scenario.schema.json is stale: vo3d schema > "
        "docs/reference/scenario.schema.json"
    )


def test_the_published_path_resolves_from_the_scenarios_folder() -> None:
    assert (ROOT / "scenarios" / PUBLISHED).resolve() == SCHEMA_FILE.resolve()


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_bundled_scenario_names_the_schema_and_validates(path: Path, validator: Any) -> None:
    assert path.read_text().splitlines()[0] == HEADER
    errors = [e.message for e in validator.iter_errors(_read(path))]
    assert errors == []


def test_every_family_draw_and_recorded_failure_validates(validator: Any) -> None:
    """What the loader accepts beyond the bundled files: the sweeps' encounters use the
    real-world keys (dynamics, wind, noise, avoids) and per-agent values."""
    datas = [
        dict(make_encounter(name, 0, i).scenario, name=f"{name}-{i}")
        for name in FAMILIES
        for i in range(3)
    ]
    datas += [_read(p) for p in sorted((ROOT / "tests" / "data").rglob("*.yaml"))]
    for data in datas:
        scenario_from_dict(data)  # the loader accepts it
        errors = [e.message for e in validator.iter_errors(data)]
        assert errors == [], data.get("name")


MINIMAL: dict[str, Any] = {
    "name": "minimal",
    "dt": 0.2,
    "max_time": 60,
    "limits": {"speed": [0, 4], "altitude": [0, 40]},
    "agents": [{"id": "u0", "start": [0, 0, 20], "goal": [50, 0, 20]}],
}


@pytest.mark.parametrize(
    "extra",
    [
        {"selector_options": {"preset": "paper"}},
        {"selector_options": {"preset": "swarm", "horizon": "sensing", "plane_step_deg": 30}},
        {"selector_options": {"horizon": 5, "corrections": ["triangle", "vo_lines"]}},
        {"defaults": {"cruise_speed": 2.0}},
        {"formulation": "sampled"},
        {"obstacles": [{"type": "box", "center": [30, 20], "size": [4, 4], "height": 30}]},
        {"dynamics": {"model": "first_order", "tau": 0.5}},
        {"sensing": {"position_noise": 0.1, "latency": 0.2, "seed": 3}},
    ],
)
def test_schema_accepts_what_the_loader_accepts(extra: dict[str, Any], validator: Any) -> None:
    data = {**MINIMAL, **extra}
    scenario_from_dict(data)
    assert [e.message for e in validator.iter_errors(data)] == []


@pytest.mark.parametrize(
    "extra",
    [
        {"selector_options": {"preset": "fastest"}},
        {"selector_options": {"reciprocal": "yes"}},
        {"selector_options": {"plane_step": 30}},
        {"defaults": {"cruise_speed": 0}},
        {"formulation": "qp"},
        {"agents": [{"id": "u0", "start": [0, 0], "goal": [50, 0, 20]}]},
        {"obstacles": [{"type": "cone", "center": [30, 20], "radius": 3, "height": 30}]},
        {"dt": "0.2"},
        {"limits": {"speed": [0, 4, 8], "altitude": [0, 40]}},
        {"colour": "red"},
    ],
)
def test_schema_refuses_what_the_loader_refuses(extra: dict[str, Any], validator: Any) -> None:
    data = {**MINIMAL, **extra}
    with pytest.raises(ScenarioError):
        scenario_from_dict(data)
    assert list(validator.iter_errors(data))


def _keys(schema: dict[str, Any]) -> set[str]:
    """Every property name anywhere in a JSON Schema."""
    found: set[str] = set()
    stack: list[Any] = [schema]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            found |= set(node.get("properties", {}))
            stack += list(node.values())
        elif isinstance(node, list):
            stack += node
    return found


def test_the_reference_pages_name_every_key(validator: Any) -> None:
    """docs/reference/scenario.md documents every key of the format (the selector options on
    the presets page), and docs/reference/summary.md every key of a run's summary."""
    docs = ROOT / "docs"
    scenario_page = (docs / "reference" / "scenario.md").read_text()
    presets_page = (docs / "guide" / "presets.md").read_text()
    options = set(validator.schema["properties"]["selector_options"]["properties"])
    missing = [k for k in _keys(validator.schema) - options if f"`{k}`" not in scenario_page]
    missing += [k for k in options if f"`{k}`" not in presets_page + scenario_page]
    assert not missing, f"keys not documented: {sorted(missing)}"

    from vo3d_opt.sim import run_scenario, summarize

    summary = summarize(run_scenario("vertical-encounter"))
    summary_page = (docs / "reference" / "summary.md").read_text()
    assert not [k for k in summary if f"`{k}`" not in summary_page]
