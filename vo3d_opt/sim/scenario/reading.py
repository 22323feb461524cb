"""Reading a scenario's YAML safely: bounded in size, depth and expansion, numbers as YAML 1.2
reads them, and every problem one line naming the file, line and key.

A scenario may come from anywhere, so the text is checked before anything is built from it:

* at most :data:`MAX_BYTES` are read (``/dev/zero`` or a huge file is refused, not parsed);
* one pass over libyaml's events (no recursion) refuses nesting deeper than
  :data:`MAX_DEPTH` and documents whose aliases would expand to more than :data:`MAX_NODES`
  nodes (a "billion laughs" file of a kilobyte);
* numbers follow YAML 1.2's core schema: ``-020`` is -20, not octal 16; ``1:30`` and ``0b101``
  are text, not 90 and 5, so a key that needs a number says so; only ``true``/``false`` are
  booleans (``yes``, ``on``: text) and dates stay text;
* duplicate keys are refused (PyYAML keeps the last silently), merge keys ``<<`` are read as
  YAML defines them.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from vo3d_opt.extras import needs

with needs("sim", "scenario files"):
    import yaml


#: The largest scenario file read (bytes): 10,000 agents take about a megabyte.
MAX_BYTES = 16 * 1024 * 1024
#: The deepest nesting of mappings and lists (a scenario needs five).
MAX_DEPTH = 32
#: The most nodes a document may hold once its aliases are expanded.
MAX_NODES = 2_000_000

_CLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class YAMLProblem(ValueError):
    """A text that is no acceptable YAML; the message is one line (``line L, column C:`` first
    when it has a place)."""


def read_text(path: Path) -> str:
    """The file's text, refused beyond :data:`MAX_BYTES` or when it is not UTF-8 (``OSError``
    for a file that cannot be read)."""
    with open(path, "rb") as fh:
        data = fh.read(MAX_BYTES + 1)
    if len(data) > MAX_BYTES:
        raise YAMLProblem(f"larger than {MAX_BYTES // 2**20} MiB: not a scenario file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YAMLProblem(f"not UTF-8 text (byte {exc.start})") from None


# --------------------------------------------------------------------------- YAML 1.2 numbers

_INT = re.compile(r"^[-+]?[0-9]+$|^0o[0-7]+$|^0x[0-9a-fA-F]+$")
_FLOAT = re.compile(
    r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?$"
    r"|^[-+]?\.(?:inf|Inf|INF)$|^\.(?:nan|NaN|NAN)$"
)
_BOOL = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_NULL = re.compile(r"^(?:~|null|Null|NULL|)$")


class _Loader(_CLoader):  # type: ignore[valid-type, misc]
    """libyaml's safe loader with YAML 1.2's core schema for plain scalars, duplicate keys
    refused and merge keys honoured."""

    yaml_implicit_resolvers: dict[Any, list[Any]] = {}


for tag, pattern, first in (
    ("tag:yaml.org,2002:bool", _BOOL, list("tTfF")),
    ("tag:yaml.org,2002:int", _INT, list("-+0123456789")),
    ("tag:yaml.org,2002:float", _FLOAT, list("-+.0123456789")),
    ("tag:yaml.org,2002:null", _NULL, ["~", "n", "N", ""]),
    ("tag:yaml.org,2002:merge", re.compile(r"^<<$"), ["<"]),
):
    _Loader.add_implicit_resolver(tag, pattern, first)


def _construct_int(loader: _Loader, node: yaml.ScalarNode) -> int:
    text = str(loader.construct_scalar(node))
    if text.startswith("0o"):
        return int(text[2:], 8)
    if text.startswith("0x"):
        return int(text[2:], 16)
    return int(text, 10)  # leading zeros are decimal in YAML 1.2


def _construct_float(loader: _Loader, node: yaml.ScalarNode) -> float:
    text = str(loader.construct_scalar(node)).lower()
    if text.endswith(".inf"):
        return float("-inf") if text.startswith("-") else float("inf")
    return float("nan") if text.endswith(".nan") else float(text)


def _construct_bool(loader: _Loader, node: yaml.ScalarNode) -> bool:
    return str(loader.construct_scalar(node)).lower() == "true"


def _construct_mapping(loader: _Loader, node: yaml.MappingNode, deep: bool = False) -> Any:
    seen: set[Any] = set()
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=deep)
        try:
            duplicate = key in seen
            seen.add(key)
        except TypeError:  # an unhashable key (a list): PyYAML refuses it itself
            continue
        if duplicate:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {str(key)[:40]!r}", key_node.start_mark
            )
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


for tag, construct in (
    ("tag:yaml.org,2002:int", _construct_int),
    ("tag:yaml.org,2002:float", _construct_float),
    ("tag:yaml.org,2002:bool", _construct_bool),
    (yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping),
):
    _Loader.add_constructor(tag, construct)


# --------------------------------------------------------------------------- bounds


def _check_events(text: str) -> None:
    """One pass over the parser's events: nesting depth and expanded size, before anything is
    composed (the composer and every later walk recurse and expand aliases)."""
    sizes: dict[str, int] = {}  # anchor -> nodes its subtree expands to
    open_counts: list[list[Any]] = []  # per open collection: [nodes, anchor]
    total = 0
    for event in yaml.parse(text, Loader=_CLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            if len(open_counts) >= MAX_DEPTH:
                raise _at(event, f"nested deeper than {MAX_DEPTH} levels")
            open_counts.append([1, event.anchor])
            continue
        if isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            nodes, anchor = open_counts.pop()
            if anchor is not None:
                sizes[anchor] = nodes
            grown = nodes
        elif isinstance(event, yaml.ScalarEvent):
            grown = 1
            if event.anchor is not None:
                sizes[event.anchor] = 1
        elif isinstance(event, yaml.AliasEvent):
            grown = sizes.get(event.anchor or "", 1)
        else:
            continue
        if open_counts:
            open_counts[-1][0] += grown
        else:
            total += grown
        if total + sum(c[0] for c in open_counts) > MAX_NODES:
            raise _at(event, f"expands to more than {MAX_NODES:,} nodes (aliases)")


def _at(event: Any, problem: str) -> YAMLProblem:
    mark = event.start_mark
    return YAMLProblem(f"line {mark.line + 1}, column {mark.column + 1}: {problem}")


def parse(text: str) -> Any:
    """The data of one YAML document, within the bounds of the module docstring;
    ``YAMLProblem`` (one line) otherwise."""
    try:
        _check_events(text)
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a safe loader
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise YAMLProblem(" ".join(f"{where}invalid YAML: {problem}".split())) from None
