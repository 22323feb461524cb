"""``vo3d schema``: the JSON Schema of a scenario file, generated from the pydantic models that
validate it (:class:`vo3d_opt.sim.scenario.Scenario` and its groups of keys).

An editor that reads JSON Schema (the YAML language server of VS Code and others) then checks
and completes a scenario as it is typed: every bundled scenario names the published copy,
``docs/reference/scenario.schema.json``, on its first line. The schema accepts every file the
loader accepts; the loader checks more (what depends on several keys: a start inside an
obstacle, a step longer than a sensing range, a latency that is no whole number of steps).

The models hold three kinds of value that pydantic cannot describe by itself, translated here:
points and vectors (``Vec2``, ``Vec3``: numpy arrays read from a list of numbers), ranges
(``Range``: two numbers) and a selector's ``horizon`` (seconds, null or ``"sensing"``). A
scenario's ``selector_options`` is a free mapping in the model, checked by
:func:`vo3d_opt.config.check_options`; its schema lists ``preset`` and every option with its
type, range and description, from the configuration's own models.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from typing import Any, Final, get_args

from pydantic.json_schema import GenerateJsonSchema, JsonSchemaValue
from pydantic_core import core_schema

from vo3d_opt import types
from vo3d_opt.config import FIELD_GROUP, GROUPS, PRESETS, SENSING, VOConfig
from vo3d_opt.selector import FORMULATIONS
from vo3d_opt.sim.scenario import Scenario

from .common import EXIT_OK

#: Where the schema is published in the repository (docs), relative to a bundled scenario.
PUBLISHED: Final = "../docs/reference/scenario.schema.json"
DIALECT: Final = "https://json-schema.org/draft/2020-12/schema"

_NUMBER: Final[dict[str, Any]] = {"type": "number"}


def _numbers(n: int) -> JsonSchemaValue:
    return {"type": "array", "items": dict(_NUMBER), "minItems": n, "maxItems": n}


def _validator(metadata: Any) -> Callable[..., Any]:
    """The function of the (only) validator among a type's or a field's metadata."""
    return next(m.func for m in metadata if hasattr(m, "func"))


#: Validators whose input is described by hand: each function is the one object that every
#: field of that type shares.
_BY_HAND: Final[dict[Callable[..., Any], JsonSchemaValue]] = {
    _validator(get_args(types.Vec2)): _numbers(2),
    _validator(get_args(types.Vec3)): _numbers(3),
    _validator(get_args(types.Range)): _numbers(2),
    _validator(VOConfig.model_fields["horizon"].metadata): {
        "anyOf": [
            {"type": "number", "exclusiveMinimum": 0, "maximum": 1e6},
            {"const": SENSING},
            {"type": "null"},
        ]
    },
}


class ScenarioSchemaGenerator(GenerateJsonSchema):
    """pydantic's generator, with the hand-described validators of :data:`_BY_HAND`."""

    def _by_hand(self, schema: Any) -> JsonSchemaValue | None:
        found = _BY_HAND.get(schema["function"]["function"])
        return json.loads(json.dumps(found)) if found is not None else None

    def function_before_schema(
        self, schema: core_schema.BeforeValidatorFunctionSchema
    ) -> JsonSchemaValue:
        return self._by_hand(schema) or super().function_before_schema(schema)

    def function_plain_schema(
        self, schema: core_schema.PlainValidatorFunctionSchema
    ) -> JsonSchemaValue:
        return self._by_hand(schema) or super().function_plain_schema(schema)


def selector_options_schema() -> JsonSchemaValue:
    """``selector_options``: ``preset`` and every option of the configuration's groups."""
    properties: dict[str, Any] = {
        "preset": {
            "enum": list(PRESETS),
            "description": "the preset the options start from (default: safe)",
        }
    }
    for group, model in GROUPS.items():
        group_schema = model.model_json_schema(schema_generator=ScenarioSchemaGenerator)
        for name, prop in group_schema["properties"].items():
            if FIELD_GROUP.get(name) == group:
                prop.pop("default", None)  # the preset's value, not the field's, applies
                prop.pop("uniqueItems", None)  # a set: the loader takes a repeated name once
                properties[name] = prop
    return {
        "type": "object",
        "description": "the selector's configuration: a preset and options over it "
        "(an option left out takes the preset's value)",
        "properties": properties,
        "additionalProperties": False,
    }


#: Bounds as pydantic's core schema names them, and as JSON Schema does.
_BOUNDS: Final = {
    "gt": "exclusiveMinimum",
    "ge": "minimum",
    "lt": "exclusiveMaximum",
    "le": "maximum",
}


def _tidy(node: Any) -> Any:
    """Bounds that pydantic leaves in its own words (a number's ``gt`` behind a validator)
    renamed, and the titles it makes up from the keys' names ("R Pz") dropped."""
    if isinstance(node, list):
        return [_tidy(x) for x in node]
    if not isinstance(node, dict):
        return node
    out = {k: _tidy(v) for k, v in node.items() if k != "title" or not isinstance(v, str)}
    if out.get("type") in ("number", "integer"):
        out = {_BOUNDS.get(k, k): v for k, v in out.items()}
    return out


def scenario_schema() -> JsonSchemaValue:
    """The JSON Schema of a scenario file (draft 2020-12)."""
    schema = Scenario.model_json_schema(schema_generator=ScenarioSchemaGenerator)
    schema["properties"]["selector_options"] = selector_options_schema()
    schema["properties"]["formulation"]["anyOf"][0] = {"enum": list(FORMULATIONS)}
    return {"$schema": DIALECT, "title": "vo3d-opt scenario", **_tidy(schema)}


def schema_text() -> str:
    """The schema as ``vo3d schema`` prints it (and as it is published): sorted keys, two
    spaces of indent, a final newline."""
    return json.dumps(scenario_schema(), indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def add_schema_parser(sub: Any, common: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "schema",
        parents=common,
        help="print the JSON Schema of a scenario file",
        description="Print the JSON Schema (draft 2020-12) of a scenario file, generated "
        "from the models that validate it. Editors that read JSON Schema check and complete "
        f"a scenario whose first line is `# yaml-language-server: $schema={PUBLISHED}` "
        "(the bundled ones do).",
    )
    p.set_defaults(func=cmd_schema)


def cmd_schema(args: argparse.Namespace) -> int:
    print(schema_text(), end="")
    return EXIT_OK
