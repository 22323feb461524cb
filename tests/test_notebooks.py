"""The notebooks: each is a jupytext pair, ``NN_name.py`` in the percent format (the source) and
``NN_name.ipynb`` (its copy for Jupyter). The suite checks that every ``.ipynb`` holds exactly
the cells of its ``.py`` (inputs only: outputs a user saved do not fail it) and runs every
``.py`` top to bottom in a fresh kernel, its figures going to a temporary folder.

The kernel is this test's own interpreter: a temporary kernel spec whose argv starts with
``sys.executable`` is put first on JUPYTER_PATH, so no kernel needs installing beforehand and
another ``python3`` kernel on the machine cannot be picked by mistake.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import jupytext
import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
NB_DIR = ROOT / "notebooks"
SOURCES = sorted(NB_DIR.glob("[0-9][0-9]_*.py"))
EXPECTED = {"01_geometry", "02_solver_comparison", "03_paper_cases", "04_rvo2_3d_baseline"}
KERNEL = "vo3d-opt-test"
#: Per-cell limit; the whole set runs in about a minute and a half on 2 cores.
CELL_TIMEOUT = 600


def _cells(nb: nbformat.NotebookNode) -> list[tuple[str, str]]:
    return [(c.cell_type, c.source) for c in nb.cells]


def test_every_notebook_is_a_pair():
    assert {p.stem for p in SOURCES} == EXPECTED
    assert {p.stem for p in NB_DIR.glob("*.ipynb")} == EXPECTED
    assert not (NB_DIR / "_build.py").exists()  # no generator: the .py files are the source


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_ipynb_holds_the_cells_of_its_py(source):
    paired = nbformat.read(source.with_suffix(".ipynb"), as_version=4)
    nbformat.validate(paired)
    assert paired.metadata["jupytext"]["formats"] == "ipynb,py:percent"
    fix = f"run: .venv/bin/jupytext --sync notebooks/{source.name}"
    assert _cells(paired) == _cells(jupytext.read(source)), fix


@pytest.fixture(scope="module")
def kernel_path(tmp_path_factory):
    d = tmp_path_factory.mktemp("jupyter")
    spec_dir = d / "kernels" / KERNEL
    spec_dir.mkdir(parents=True)
    (spec_dir / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "vo3d-opt tests", "language": "python",
    }))
    return d


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_notebook_runs_and_writes_its_figures(source, kernel_path, monkeypatch, tmp_path):
    monkeypatch.setenv("JUPYTER_PATH", str(kernel_path))
    monkeypatch.setenv("VO3D_NB_OUT", str(tmp_path))
    monkeypatch.delenv("VO3D_NB_FULL", raising=False)
    nb = jupytext.read(source)
    client = NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name=KERNEL,
                            resources={"metadata": {"path": str(NB_DIR)}})
    t0 = time.perf_counter()
    client.execute()  # raises CellExecutionError with the failing cell and traceback
    elapsed = time.perf_counter() - t0
    outputs = [o for c in nb.cells for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    figures = tmp_path / source.stem
    assert any(figures.rglob("*.png")), f"no figure in {figures}"
    said = "".join(o.get("text", "") for o in outputs if o.get("output_type") == "stream")
    assert f"figures of this notebook are written to {figures}" in said
    print(f"{source.stem}: {elapsed:.1f} s")
