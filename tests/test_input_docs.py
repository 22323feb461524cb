"""docs/input.md states every selector option's accepted range: each row is checked against
the configuration's own bounds, so the page cannot drift from the code."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from vo3d_opt.config import OPTION_KEYS, PRESETS, SelectorConfig

PAGE = Path(__file__).resolve().parents[1] / "docs" / "input.md"


def _rows() -> dict[str, str]:
    rows = {}
    for line in PAGE.read_text().splitlines():
        m = re.match(r"\| `(\w+)` \| (.*?) \|", line)
        if m:
            rows[m.group(1)] = m.group(2)
    return rows


def _bounds(option: str) -> tuple[float | None, float | None]:
    """The field's lower and upper bounds from the configuration's JSON Schema."""
    schema = SelectorConfig.model_json_schema()
    for group in schema["$defs"].values():
        field = group.get("properties", {}).get(option)
        if field is None:
            continue
        for part in [field, *field.get("anyOf", [])]:
            lo = part.get("minimum", part.get("ge", part.get("exclusiveMinimum", part.get("gt"))))
            hi = part.get("maximum", part.get("le"))
            if lo is not None or hi is not None:
                return lo, hi
        return None, None
    raise AssertionError(f"{option}: not a configuration field")


def test_every_option_has_a_row():
    assert set(_rows()) == set(OPTION_KEYS)


@pytest.mark.parametrize("option", [k for k in OPTION_KEYS if k != "preset"])
def test_each_documented_range_is_the_configurations(option):
    lo, hi = _bounds(option)
    text = _rows()[option]
    numbers = [float(x) for x in re.findall(r"(?<![\w.])(\d+(?:\.\d+)?(?:e\d+)?)", text)]
    for bound in (lo, hi):
        if bound is not None:
            assert float(bound) in numbers, f"{option}: {bound} not in {text!r}"


def test_the_presets_are_listed():
    assert all(f"`{name}`" in _rows()["preset"] for name in PRESETS)
