"""Every ```python block of the README and of the documentation (docs/ and the formulation
notes it includes) runs as written: each in a fresh interpreter, from an empty temporary
directory, so imports must be in the block and paths must work from anywhere (bundled
scenarios by name). A block preceded by the line ``<!-- no-run -->`` is shown, not run (used
for what needs hardware or a network: the vehicle link)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NO_RUN = "<!-- no-run -->"
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def documents() -> list[Path]:
    return [
        ROOT / "README.md",
        *sorted((ROOT / "docs").rglob("*.md")),
        *sorted((ROOT / "formulations").glob("*.md")),
    ]


def blocks(path: Path) -> list[tuple[int, str]]:
    """(line, code) of every python block of ``path`` not marked ``no-run``."""
    text = path.read_text()
    out = []
    for match in _BLOCK.finditer(text):
        before = text[: match.start()].rstrip("\n").rsplit("\n", 1)[-1]
        if before.strip() != NO_RUN:
            out.append((text.count("\n", 0, match.start()) + 1, match.group(1)))
    return out


EXAMPLES = [
    pytest.param(code, id=f"{path.relative_to(ROOT)}:{line}")
    for path in documents()
    for line, code in blocks(path)
]


def test_the_documents_have_examples() -> None:
    readme = [p for p in EXAMPLES if p.id.startswith("README.md")]
    assert len(readme) >= 3 and len(EXAMPLES) > len(readme)


@pytest.mark.parametrize("code", EXAMPLES)
def test_example_runs_as_written(code: str, tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert result.returncode == 0, result.stderr[-3000:]


_YAML = re.compile(r"^```yaml\n(.*?)^```", re.S | re.M)


def test_whole_scenarios_in_the_documents_load() -> None:
    """A ```yaml block that is a whole scenario (it has a ``name``) loads as written; the others
    are fragments of one."""
    from vo3d_opt.sim.scenario import scenario_from_dict
    from vo3d_opt.sim.scenario.reading import parse

    whole = 0
    for path in documents():
        for match in _YAML.finditer(path.read_text()):
            data = parse(match.group(1))
            if isinstance(data, dict) and "name" in data:
                scenario_from_dict(data, source=str(path.relative_to(ROOT)))
                whole += 1
    assert whole >= 1
