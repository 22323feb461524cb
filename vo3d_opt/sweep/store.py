"""A sweep's rows on disk as they come (``vo3d sweep --out DIR``), so that nothing flown is lost
and ``--resume`` flies only what is missing.

* ``DIR/sweep.json``: what the sweep is (family, encounters, seed, method, formulation, solver,
  selector options, a digest of what the family draws), written when it starts: ``--resume``
  refuses a directory whose sweep is another, naming what differs, and a sweep without
  ``--resume`` or ``--overwrite`` refuses a directory that holds one (:func:`check_out`);
* ``DIR/parts/part-NNNNNN.parquet``: the rows of the encounters flown so far, a part every few
  seconds (:data:`FLUSH_SECONDS`) or :data:`FLUSH_ROWS` rows, and whatever is complete when the
  sweep is interrupted (a signal, an exception); each written under a temporary name and
  renamed, so a part is whole or absent. A client killed outright loses only the rows it had
  not written yet: those encounters are flown again;
* when the sweep ends, ``output.write_results`` writes ``encounters.parquet`` (every row),
  the figures, the failures and ``summary.json`` last, and the parts are removed: an
  interrupted and resumed sweep leaves exactly the files of one that ran straight through.

Rows go to disk and back as plain values (int, float, str, bool, None; Arrow keeps each bit),
and :func:`rows_frame` turns any list of rows into the table the same way, so the table does
not depend on which rows were flown in which sitting.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vo3d_opt.extras import needs
from vo3d_opt.report import atomic

if TYPE_CHECKING:
    import pandas as pd

MANIFEST = "sweep.json"
PARTS = "parts"
#: A part is written when this many rows are waiting, or this many seconds after the last.
FLUSH_ROWS = 1000
FLUSH_SECONDS = 5.0
#: The files a finished sweep writes besides the manifest (removed when a new sweep starts).
OUTPUTS = ("summary.json", "encounters.parquet", "min_distance.png", "failures")


class ResumeError(ValueError):
    """``--out DIR`` holds a sweep that this one may not continue or write over."""


def failed(row: dict[str, Any]) -> bool:
    """Whether ``row`` holds an error where a flight's results would be."""
    return row.get("error") is not None


def _keep(rows: dict[int, dict[str, Any]], row: dict[str, Any]) -> None:
    """Keep ``row`` under its index unless a row is there already; an error gives way to a row
    flown again (it may have been the cluster's, a worker or scheduler lost, not the
    encounter's)."""
    index = int(row["index"])
    if index not in rows or failed(rows[index]):
        rows[index] = row


def rows_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per encounter, sorted by index, its columns the keys of the rows in the order
    they first appear (a key a row lacks is None there)."""
    with needs("sweep", "sweep output"):
        import pandas as pd

    ordered = sorted(rows, key=lambda r: int(r["index"]))
    keys: dict[str, None] = {}
    for row in ordered:
        keys.update(dict.fromkeys(row))
    columns = list(keys)
    return pd.DataFrame([[r.get(k) for k in columns] for r in ordered], columns=columns)


def _write_part(rows: list[dict[str, Any]], path: Path) -> None:
    with needs("sweep", "sweep output"):
        import pyarrow as pa
        import pyarrow.parquet as pq

    keys: dict[str, None] = {}
    for row in rows:
        keys.update(dict.fromkeys(row))
    table = pa.table({k: pa.array([r.get(k) for r in rows]) for k in keys})
    with atomic(path) as tmp:
        pq.write_table(table, tmp)


def _read_rows(path: Path) -> list[dict[str, Any]]:
    with needs("sweep", "sweep output"):
        import pyarrow.parquet as pq

    return list(pq.read_table(path).to_pylist())


def differences(want: dict[str, Any], have: dict[str, Any]) -> list[str]:
    """``key: have -> want`` for each key of ``want`` whose value differs in ``have``."""
    return [
        f"{key}: {json.dumps(have.get(key))} there, {json.dumps(value)} now"
        for key, value in want.items()
        if have.get(key) != value
    ]


def manifest_in(out: Path) -> dict[str, Any] | None:
    """The manifest of the sweep in ``out``, None when there is none."""
    path = out / MANIFEST
    if not path.exists():
        return None
    try:
        found = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ResumeError(f"--out {out}: {MANIFEST} is unreadable ({exc})") from None
    if not isinstance(found, dict):
        raise ResumeError(f"--out {out}: {MANIFEST} is not a sweep's")
    return found


def check_out(
    out: str | Path, manifest: dict[str, Any], *, resume: bool, overwrite: bool = False
) -> dict[str, Any] | None:
    """The manifest of the sweep already in ``out`` (None: none, or ``overwrite``), or
    ``ResumeError`` when the sweep described by ``manifest`` may not write there: with
    ``resume``, a sweep of other arguments is there; without ``resume`` or ``overwrite``, any
    sweep is there, finished or not (its rows would be lost). Nothing is written."""
    out = Path(out)
    if resume and overwrite:
        raise ResumeError("--resume, --overwrite: give one of them")
    if overwrite:
        return None
    found = manifest_in(out)
    if found is None:
        return None
    wrong = differences(manifest, found)
    if resume and wrong:
        older = "" if "draws" in found else "; started by a version that did not record them"
        raise ResumeError(f"--resume: {out} holds another sweep ({'; '.join(wrong)}{older})")
    if not resume:
        state = "a finished" if (out / "summary.json").exists() else "an unfinished"
        kind = f" of other arguments ({'; '.join(wrong)})" if wrong else ""
        keep = "" if wrong else "continue or keep it with --resume, "
        raise ResumeError(
            f"--out {out}: holds {state} sweep{kind}; {keep}replace it with --overwrite, "
            "or give another directory"
        )
    return found


class PartStore:
    """The rows of a sweep in ``out`` (the module docstring). ``manifest``: what the sweep is;
    ``resume``, ``overwrite``: as for :func:`check_out`; a sweep not resumed starts afresh.
    ``rows``: those flown before, by index."""

    def __init__(
        self,
        out: str | Path,
        manifest: dict[str, Any],
        resume: bool,
        flush_seconds: float = FLUSH_SECONDS,
        overwrite: bool = False,
    ) -> None:
        self.out = Path(out)
        self.flush_seconds = float(flush_seconds)
        self.parts = self.out / PARTS
        self.manifest = manifest
        self.pending: list[dict[str, Any]] = []
        self.last_flush = time.monotonic()
        found = check_out(self.out, manifest, resume=resume, overwrite=overwrite)
        if found is None:  # nothing there, or replaced (overwrite)
            self._clear()
            with atomic(self.out / MANIFEST) as tmp:
                tmp.write_text(json.dumps(manifest, indent=2) + "\n")
        self.rows = self._read()

    def _clear(self) -> None:
        """Remove an earlier sweep's files (``summary.json`` first: incomplete until the end)."""
        for name in OUTPUTS:
            path = self.out / name
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink(missing_ok=True)
        shutil.rmtree(self.parts, ignore_errors=True)

    def _read(self) -> dict[int, dict[str, Any]]:
        """The rows already on disk: a finished sweep's table, then the parts (the first row
        of an index kept, unless it is an error and a later one is not); a temporary file a
        killed writer left behind is removed."""
        rows: dict[int, dict[str, Any]] = {}
        sources = [self.out / "encounters.parquet"] if (self.out / "summary.json").exists() else []
        if self.parts.is_dir():
            for stale in self.parts.glob(".*"):
                stale.unlink(missing_ok=True)
            sources += sorted(self.parts.glob("part-*.parquet"))
        for path in sources:
            if path.exists():
                for row in _read_rows(path):
                    _keep(rows, row)
        return rows

    def add(self, rows: list[dict[str, Any]]) -> None:
        """Keep ``rows``; write a part when enough are waiting or enough time has passed."""
        for row in rows:
            _keep(self.rows, row)
        self.pending += rows
        waited = time.monotonic() - self.last_flush
        if len(self.pending) >= FLUSH_ROWS or (self.pending and waited >= self.flush_seconds):
            self.flush()

    def flush(self) -> None:
        """Write the waiting rows as the next part (nothing when none wait)."""
        self.last_flush = time.monotonic()
        if not self.pending:
            return
        self.parts.mkdir(parents=True, exist_ok=True)
        numbers = [int(p.stem.split("-")[1]) for p in self.parts.glob("part-*.parquet")]
        _write_part(self.pending, self.parts / f"part-{max(numbers, default=0) + 1:06d}.parquet")
        self.pending = []

    def finish(self) -> None:
        """After the outputs are written: the parts are no longer needed."""
        shutil.rmtree(self.parts, ignore_errors=True)
