"""What the notebooks of this folder share: the project's root, the folder their figures go to,
and two small helpers for tables.

Figures go to ``out/notebooks/<notebook>/`` under the project's root, or under the folder named
by the environment variable ``VO3D_NB_OUT`` (the test suite points it at a temporary folder).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from IPython.display import Markdown
from matplotlib.figure import Figure

ROOT = next(p for p in [Path.cwd(), *Path.cwd().parents] if (p / "pyproject.toml").exists())


def figure_dir(notebook: str) -> Path:
    """The folder this notebook's figures are written to (created), printed for the reader."""
    base = Path(os.environ.get("VO3D_NB_OUT") or ROOT / "out" / "notebooks")
    out = (base / notebook).resolve()
    out.mkdir(parents=True, exist_ok=True)
    print(f"figures of this notebook are written to {out}")
    return out


def save(fig: Figure, folder: Path, name: str, dpi: int = 150) -> Path:
    """Write ``fig`` as ``folder/name.png`` (cropped) and return the path."""
    path = folder / f"{name}.png"
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    return path


def md_table(header: list, rows: list[list]) -> Markdown:
    """A markdown table (pandas is not a dependency)."""
    out = ["| " + " | ".join(map(str, header)) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(map(str, r)) + " |" for r in rows]
    return Markdown("\n".join(out))


def fmt(x: float | None, spec: str = ".3f") -> str:
    """A number for a table; a dash for None, NaN or inf."""
    return "—" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)
