"""Reading scenario files: YAML, the bundled scenarios by name, and one-line errors.

:func:`load_scenario` logs (``logging``, level WARNING) what is allowed but worth saying:
``Scenario.warnings()``, e.g. a start inside a protected zone.

Rejected, with one :class:`ScenarioError` line ``FILE: key.path[2].key: problem`` listing every
problem found (``; `` between them): unreadable files, invalid YAML, duplicate YAML keys, and
whatever the schema (:mod:`vo3d_opt.sim.scenario.schema`) refuses: unknown or missing keys
(with a hint: a close key name, or where a key that is valid elsewhere belongs), wrong types,
NaN or infinite numbers, impossible values, cross-field problems.

YAML 1.1 (PyYAML) reads ``1e9`` as a string; this loader reads it as YAML 1.2 does, a number.
A name without a directory or ``.yaml`` suffix that is no file is looked up among the bundled
scenarios (file stem or ``name``); when none matches, the error suggests close names.
"""

from __future__ import annotations

import difflib
import importlib.resources
import logging
from collections import defaultdict
from functools import cache
from pathlib import Path
from typing import Annotated, Any, get_args, get_origin

from pydantic import BaseModel, ValidationError

from vo3d_opt.config import OPTION_KEYS, check_options
from vo3d_opt.sim.scenario import reading
from vo3d_opt.sim.scenario.schema import (
    OBSTACLE_TAGS,
    Scenario,
)
from vo3d_opt.types import InputError, describe_error, field_path, one_line

log = logging.getLogger(__name__)


class ScenarioError(ValueError):
    """An unreadable or invalid scenario file; the message is one line: ``file: key: problem``."""


# ------------------------------------------------------------------------------------- YAML


def _parse(text: str, source: str) -> Any:
    try:
        return reading.parse(text)
    except reading.YAMLProblem as exc:
        raise ScenarioError(one_line(f"{source}: {exc}")) from None


# ----------------------------------------------------------------------------------- errors


def _is_list(annotation: Any) -> bool:
    origin = get_origin(annotation)
    return origin is list or (origin is Annotated and _is_list(get_args(annotation)[0]))


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    """The pydantic models an annotation holds (through list, Optional, Union, Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in get_args(annotation) for m in _models_in(arg)]


@cache
def _key_places() -> dict[str, tuple[str, ...]]:
    """Every key of the format and where it is valid ("" for the top level)."""
    places: dict[str, list[str]] = defaultdict(list)

    def walk(model: type[BaseModel], where: str) -> None:
        for key, info in model.model_fields.items():
            if where not in places[key]:
                places[key].append(where)
            for sub in _models_in(info.annotation):
                walk(
                    sub, f"{where}.{key}".lstrip(".") + ("[]" if _is_list(info.annotation) else "")
                )

    walk(Scenario, "")
    for key in OPTION_KEYS:
        places[key].append("selector_options")
    return {k: tuple(v) for k, v in places.items()}


def _unknown_key(loc: tuple[Any, ...]) -> str:
    key = str(loc[-1]) if loc else "?"
    places = _key_places()
    if key in places:
        where = " and ".join(
            "at the top level of the scenario" if p == "" else f"in {p}" for p in places[key]
        )
        return f"unknown key here ({key!r} belongs {where})"
    here = _place_of(loc[:-1])  # hints among the keys valid where this one stands
    near = sorted(k for k, ps in places.items() if here in ps)
    hint = difflib.get_close_matches(key, near or sorted(places), n=1)
    return "unknown key" + (f" (did you mean {hint[0]!r}?)" if hint else "")


def _place_of(loc: tuple[Any, ...]) -> str:
    """A location as ``_key_places`` names places: ``agents[]``, ``selector_options``, ""."""
    parts: list[str] = []
    for x in loc:
        if isinstance(x, int):
            if parts:
                parts[-1] += "[]"
        elif x not in OBSTACLE_TAGS:
            parts.append(str(x))
    return ".".join(parts)


def _describe(err: Any) -> tuple[str, str]:
    """(key path, problem) of one pydantic error, in the words of a file's keys."""
    loc = tuple(err.get("loc", ()))
    kind = err.get("type", "")
    path = field_path(loc, skip=OBSTACLE_TAGS)
    if kind == "missing":
        return path, "missing required key"
    if kind == "extra_forbidden":
        return path, _unknown_key(loc)
    if kind == "union_tag_invalid":
        tag = err.get("ctx", {}).get("tag", "?")
        expected = " or ".join(repr(t) for t in sorted(OBSTACLE_TAGS))
        return f"{path}.type", f"unknown obstacle type {tag!r} (expected {expected})"
    if kind == "union_tag_not_found":
        return f"{path}.type", "missing required key"
    return path, describe_error(err, skip=OBSTACLE_TAGS)[1]


def _fail(source: str, problems: list[tuple[str, str]]) -> ScenarioError:
    text = "; ".join(f"{path}: {msg}" if path else msg for path, msg in problems)
    return ScenarioError(one_line(f"{source}: {text}"))


# ---------------------------------------------------------------------------------- loading


def scenario_from_dict(data: Any, source: str = "<scenario>") -> Scenario:
    """Validate already-parsed YAML data; ``source`` names it in error messages."""
    if not isinstance(data, dict):
        raise _fail(source, [("", f"must be a YAML mapping of keys, got {type(data).__name__}")])
    try:
        sc = Scenario.model_validate(data)
    except ValidationError as exc:
        raise _fail(source, [_describe(e) for e in exc.errors()]) from None
    sc._source = source
    return sc


def load_scenario(path: str | Path, *, warn: bool = True) -> Scenario:
    """Read and validate a scenario file, or a bundled scenario by name (see :func:`resolve`);
    raise :class:`ScenarioError` (one line) if unreadable or invalid. ``warn``: log what
    :meth:`Scenario.warnings` finds (starts inside a zone...)."""
    path = resolve(path)
    source = str(path)
    if _is_name(path):
        raise ScenarioError(f"{source}: no such file or bundled scenario{_suggestion(source)}")
    try:
        text = reading.read_text(path)
    except reading.YAMLProblem as exc:
        raise ScenarioError(f"{source}: {exc}") from None
    except OSError as exc:
        raise ScenarioError(f"{source}: cannot read: {exc.strerror or exc}") from None
    sc = scenario_from_dict(_parse(text, source), source)
    for warning in sc.warnings() if warn else ():
        log.warning("%s: %s", sc.name, warning)
    return sc


# ---------------------------------------------------------------------------- bundled files


def bundled_dir() -> Path:
    """The bundled scenarios: the package data ``vo3d_opt/scenarios`` of an installed wheel
    (built from the repository's top-level ``scenarios/``, see pyproject.toml), else that
    top-level folder itself (a source checkout or an editable install)."""
    packaged = importlib.resources.files("vo3d_opt") / "scenarios"
    if packaged.is_dir():
        return Path(str(packaged))
    return Path(__file__).resolve().parents[3] / "scenarios"


def bundled_files() -> list[Path]:
    """Every bundled scenario file, sorted by file name."""
    d = bundled_dir()
    return sorted(d.glob("*.yaml")) if d.is_dir() else []


def _is_name(p: Path) -> bool:
    return not p.exists() and p.suffix not in (".yaml", ".yml") and len(p.parts) == 1


def resolve(arg: str | Path) -> Path:
    """A scenario argument: an existing path, else a bundled scenario's name or file stem."""
    p = Path(arg)
    if not _is_name(p):
        return p
    for f in bundled_files():
        if f.stem == str(arg):
            return f
    for f in bundled_files():
        try:
            if scenario_from_dict(_parse(reading.read_text(f), str(f))).name == str(arg):
                return f
        except (OSError, ScenarioError, reading.YAMLProblem):
            continue
    return p


def close_names(arg: str) -> list[str]:
    """Bundled scenario names that ``arg`` may have meant: those containing it, else the close
    ones by spelling."""
    stems = [f.stem for f in bundled_files()]
    containing = [s for s in stems if arg and arg in s]
    return containing[:5] or difflib.get_close_matches(arg, stems, n=3, cutoff=0.5)


def _suggestion(name: str) -> str:
    names = close_names(name)
    found = f"; bundled scenarios with a close name: {', '.join(names)}" if names else ""
    return f"{found} (`vo3d list` lists the bundled scenarios)"


def parse_option(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` from a command line: the key, and the value read as a scenario file's
    value would be (YAML: ``true``, ``0.5``, ``[1, 2]``, ``1e-3``; an empty value is null);
    ``ScenarioError`` for text without a key or with a value that is no YAML."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ScenarioError(f"expected KEY=VALUE, got {text!r}")
    return key.strip(), _parse(value, f"selector_options.{key.strip()}")


def check_selector_options(options: dict[str, Any], source: str) -> dict[str, Any]:
    """``options`` checked as a scenario's ``selector_options`` would be (``ScenarioError``
    naming ``selector_options.KEY``, ``source`` first); returned validated, as a file would
    hold them (JSON types: a set of corrections becomes a list), in key order."""
    try:
        return check_options(options)
    except InputError as exc:
        raise _fail(source, [(f"selector_options.{k}", m) for k, m in exc.problems]) from None


def scenario_variant(sc: Scenario, **keys: Any) -> Scenario:
    """``sc`` with some top-level keys replaced and validated again (errors name ``sc``'s
    file): a mapping given for a mapping key (``sensing``, ``safety``, ``limits``, ...) is
    merged into it; ``dynamics`` replaces ``velocity_response_tau`` (its alias)."""
    data = sc.model_dump(exclude_none=True)
    for key, value in keys.items():
        old = data.get(key)
        data[key] = {**old, **value} if isinstance(old, dict) and isinstance(value, dict) else value
    if "dynamics" in keys:
        data.pop("velocity_response_tau", None)
    return scenario_from_dict(data, sc.source)
