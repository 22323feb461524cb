"""The documentation site builds with ``mkdocs build --strict`` (mkdocs.yml): a broken link, a
page missing from the navigation, a reference to a renamed function in the API pages or an
include of a formulation note that moved fails here, as in ``make docs``."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(
    any(
        importlib.util.find_spec(m) is None
        for m in ("mkdocs", "material", "mkdocstrings_handlers", "mkdocs_include_markdown_plugin")
    ),
    reason="the documentation tools are not installed (pip install 'vo3d-opt[docs]')",
)


def test_site_builds_strictly(tmp_path: Path) -> None:
    site = tmp_path / "site"
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert result.returncode == 0, result.stderr[-5000:]
    for page in (
        "index.html",
        "reference/api/selector/index.html",
        "formulations/plane_qp/index.html",
    ):
        assert (site / page).is_file(), page
    plane_qp = (site / "formulations/plane_qp/index.html").read_text()
    assert "exact2d" in plane_qp  # the note itself is included, not only its title
    api = (site / "reference/api/selector/index.html").read_text()
    assert "select_many" in api
    assert (site / "reference/scenario.schema.json").is_file()
