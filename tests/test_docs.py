"""The documentation site builds with ``mkdocs build --strict`` (mkdocs.yml): a broken link, a
page missing from the navigation, a reference to a renamed function in the API pages or an
include of a formulation note that moved fails here, as in ``make docs``."""

from __future__ import annotations

import importlib.util
import os
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


def test_site_builds_strictly(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from mkdocs.commands.build import build
    from mkdocs.config import load_config
    from mkdocs.exceptions import Abort

    monkeypatch.chdir(ROOT)  # mkdocstrings reads the package from the repository (paths: [.])
    monkeypatch.setenv("NO_MKDOCS_2_WARNING", "1")
    site = tmp_path / "site"
    config = load_config(str(ROOT / "mkdocs.yml"), strict=True, site_dir=str(site))
    try:
        build(config)
    except Abort as exc:  # the warnings themselves are in the captured log
        pytest.fail(f"mkdocs build --strict: {exc}")
    for page in ("index.html", "reference/api/selector.html"):
        assert (site / page).is_file(), page
    plane_qp = (site / "formulations/plane_qp.html").read_text()
    assert "exact2d" in plane_qp  # the note itself is included, not only its title
    assert 'href="getting-started.html"' in (site / "index.html").read_text()  # browsable from disk
    assert "select_many" in (site / "reference/api/selector.html").read_text()
    assert (site / "reference/scenario.schema.json").is_file()
    assert os.path.getsize(site / "figures/paper-case1-ten-uav-crossing/top_view.png") > 0
