"""What a run leaves on disk (``vo3d run --out DIR``, ``make demo``): the trajectories, the
summary and the figures. One module for the CLI and the demo.

* ``trajectories.parquet``: one row per agent and sample (pandas: ``pd.read_parquet``), the
  columns of :data:`COLUMNS`; written a chunk of steps at a time, so a 10,000-agent run never
  holds the whole table in memory;
* ``trajectories.csv``: the same rows as text, up to :data:`CSV_MAX_ROWS` rows (agents × samples);
  a larger run writes only the Parquet file (a CSV of a million rows is over 100 MB and takes
  longer to write than many runs take to fly);
* ``summary.json``: the run's summary (``vo3d_opt.sim.metrics.summarize``), floats to
  :data:`JSON_DIGITS` significant digits;
* the figures of ``vo3d_opt.figures`` and, when asked, ``animation.gif``.

Every file is written under a temporary name in the same directory and renamed into place once
complete (a rename replaces a symbolic link planted there, never the file it points to), and
``summary.json`` comes last: before anything else, the files of an earlier run in the
directory (this module's names, in every figure format) are removed, so a directory holding
``summary.json`` holds this run's complete output, and one interrupted while writing (Ctrl-C, a
full disk) has no ``summary.json`` and no half-written file under a final name.
"""

from __future__ import annotations

import contextlib
import csv
import json
import logging
import math
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.sim.record import RunRecord

log = logging.getLogger(__name__)

#: The trajectory columns: the velocity columns hold the velocity flown from that sample to the
#: next (``cmd_*``: the command), empty / NaN on the last sample, as are ``status`` and
#: ``decision_time_us`` for agents that did not decide.
COLUMNS = [
    "step",
    "time",
    "agent",
    "x",
    "y",
    "z",
    "vx",
    "vy",
    "vz",
    "cmd_vx",
    "cmd_vy",
    "cmd_vz",
    "status",
    "decision_time_us",
    "arrived",
]
#: Above this many rows (agents × samples) ``write_outputs`` writes no CSV, only Parquet.
CSV_MAX_ROWS = 500_000
#: Significant digits of the floats in JSON output (17 show rounding noise: 31.200000000000003).
JSON_DIGITS = 12
#: Samples per Parquet row group.
_PARQUET_STEPS = 200


def rounded(value: Any) -> Any:
    """``value`` with every finite float cut to JSON_DIGITS significant digits."""
    if isinstance(value, float) and math.isfinite(value):
        return float(f"{value:.{JSON_DIGITS}g}")
    if isinstance(value, dict):
        return {k: rounded(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [rounded(v) for v in value]
    return value


_UMASK = os.umask(0o022)
os.umask(_UMASK)


@contextlib.contextmanager
def _interrupt_held() -> Iterator[None]:
    """A Ctrl-C (SIGINT) during the block is recorded and raised after it: a temporary file or
    directory is never created or removed half, nor left behind by an interrupt between its
    creation and the cleanup that removes it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[tuple[int, Any]] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append((signum, frame)))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught and callable(previous):
        previous(*caught[0])
    elif caught and previous == signal.SIG_DFL:
        raise KeyboardInterrupt


@contextlib.contextmanager
def atomic(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write; renamed to ``path`` when the block ends
    normally, removed when it raises (an interrupt included)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp: Path | None = None
    try:
        with _interrupt_held():
            fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
            tmp = Path(name)
            os.close(fd)
        os.chmod(tmp, 0o666 & ~_UMASK)  # what open() would give the file, not mkstemp's 0600
        yield tmp
        with _interrupt_held():
            os.replace(tmp, path)
    finally:
        if tmp is not None:
            with _interrupt_held():
                tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def _scratch_dir(parent: Path, prefix: str) -> Iterator[Path]:
    """A temporary directory in ``parent``, removed whole however the block ends."""
    path: Path | None = None
    try:
        with _interrupt_held():
            path = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
        yield path
    finally:
        if path is not None:
            with _interrupt_held():
                shutil.rmtree(path, ignore_errors=True)


def write_summary(summary: dict[str, Any], path: str | Path) -> Path:
    path = Path(path)
    with atomic(path) as tmp:
        tmp.write_text(json.dumps(rounded(summary), indent=2, allow_nan=False) + "\n")
    return path


def write_csv(record: RunRecord, path: str | Path) -> Path:
    """Trajectories as CSV, one row per (sample, agent), the columns of :data:`COLUMNS`."""
    path = Path(path)
    ids, steps, names = record.ids, record.steps, record.status_names
    with atomic(path) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for k in range(steps + 1):
            t = f"{record.times[k]:.6g}"
            for i, name in enumerate(ids):
                x, y, z = (f"{c:.6f}" for c in record.positions[k, i])
                if k < steps:
                    v = [f"{c:.6f}" for c in record.velocities[k, i]]
                    c = [f"{c:.6f}" for c in record.commands[k, i]]
                    st = names[record.status_codes[k, i]]
                    dtu = record.decision_times[k, i]
                    dtu = "" if np.isnan(dtu) else f"{dtu * 1e6:.1f}"
                else:
                    v, c, st, dtu = ["", "", ""], ["", "", ""], "", ""
                w.writerow([k, t, name, x, y, z, *v, *c, st, dtu, int(record.arrived[k, i])])
    return path


def _table(record: RunRecord, lo: int, hi: int) -> Any:
    """Samples lo <= k < hi as a pyarrow table of :data:`COLUMNS`."""
    with needs("sim", "Parquet output"):
        import pyarrow as pa

    n, steps = record.n_agents, record.steps
    k = np.arange(lo, hi)
    flown = np.minimum(k, steps - 1)  # the last sample has no step after it: NaN below
    last = (k >= steps)[:, None]

    def per_step(a: np.ndarray) -> np.ndarray:
        out = a[flown] if steps else np.full((len(k), n) + a.shape[2:], np.nan)
        return np.where(last[..., None] if out.ndim == 3 else last, np.nan, out)

    vel, cmd = per_step(record.velocities), per_step(record.commands)
    codes = record.status_codes[flown] if steps else np.zeros((len(k), n), dtype=np.uint16)
    codes = np.where(last, 0, codes).astype(np.int32)  # code 0: "", no decision
    cols = {
        "step": np.repeat(k, n).astype(np.int32),
        "time": np.repeat(record.times[lo:hi], n),
        "agent": pa.DictionaryArray.from_arrays(
            np.tile(np.arange(n, dtype=np.int32), len(k)), pa.array(record.ids)
        ),
        **{c: record.positions[lo:hi, :, j].ravel() for j, c in enumerate("xyz")},
        **{f"v{c}": vel[..., j].ravel() for j, c in enumerate("xyz")},
        **{f"cmd_v{c}": cmd[..., j].ravel() for j, c in enumerate("xyz")},
        "status": pa.DictionaryArray.from_arrays(codes.ravel(), pa.array(record.status_names)),
        "decision_time_us": per_step(record.decision_times).ravel() * 1e6,
        "arrived": record.arrived[lo:hi].ravel(),
    }
    return pa.table(cols)


def write_parquet(record: RunRecord, path: str | Path) -> Path:
    """Trajectories as Parquet, one row per (sample, agent), the columns of :data:`COLUMNS`
    (``agent`` and ``status`` dictionary-encoded), a row group per 200 samples."""
    with needs("sim", "Parquet output"):
        import pyarrow.parquet as pq

    path = Path(path)
    samples = record.steps + 1
    with atomic(path) as tmp:
        writer = None
        try:
            for lo in range(0, samples, _PARQUET_STEPS):
                table = _table(record, lo, min(samples, lo + _PARQUET_STEPS))
                if writer is None:
                    writer = pq.ParquetWriter(tmp, table.schema)
                writer.write_table(table)
                record.drop_resident()
        finally:
            if writer is not None:
                writer.close()
    return path


def write_outputs(
    record: RunRecord,
    summary: dict[str, Any],
    out: Path,
    *,
    plot_options: dict[str, Any] | None = None,
    animate: bool = False,
) -> list[Path]:
    """trajectories.parquet, trajectories.csv (up to CSV_MAX_ROWS rows), summary.json, the
    figures (``plot_options``: ``write_plots``' keywords) and with ``animate`` animation.gif of
    a run in ``out``; the paths written."""
    from vo3d_opt.figures import skipped_plots, write_plots  # matplotlib only when asked for

    out.mkdir(parents=True, exist_ok=True)
    _remove_earlier(out)
    written = [write_parquet(record, out / "trajectories.parquet")]
    rows = record.n_agents * (record.steps + 1)
    if rows <= CSV_MAX_ROWS:
        written.append(write_csv(record, out / "trajectories.csv"))
    else:
        log.info(
            "not written: trajectories.csv (%d rows, more than %d; trajectories.parquet has them)",
            rows,
            CSV_MAX_ROWS,
        )
    with _scratch_dir(out, ".figures.") as scratch:
        drawn = write_plots(record, scratch, **(plot_options or {}))
        if animate:
            from vo3d_opt.animation import write_animation

            drawn.append(write_animation(record, scratch / "animation.gif"))
        for path in drawn:
            with _interrupt_held():  # a figure is in place and counted, or not
                os.replace(path, out / path.name)
                written.append(out / path.name)
    for name, why in skipped_plots(record).items():
        log.info("not drawn: %s (%s)", name, why)
    written.append(write_summary(summary, out / "summary.json"))  # last: the run is complete
    return written


#: The figures ``write_plots`` may draw (their file stems).
FIGURE_STEMS = ("trajectories_3d", "top_view", "vehicle_distance", "obstacle_distance")
#: The names a run's output takes (figures in every format): removed before a new run's.
OUTPUT_GLOBS = (
    "summary.json",
    "trajectories.parquet",
    "trajectories.csv",
    "animation.gif",
    "*.png",
    "*.pdf",
    "*.svg",
)


def _remove_earlier(out: Path) -> None:
    """Remove an earlier run's files from ``out`` (``summary.json`` first, so the directory
    reads as incomplete until this run's is written); only this module's own names, and only
    figures this module draws."""
    for pattern in OUTPUT_GLOBS:
        for path in sorted(out.glob(pattern)):
            figure = pattern.startswith("*")
            if not figure or path.stem in FIGURE_STEMS:
                path.unlink(missing_ok=True)


__all__ = [
    "COLUMNS",
    "CSV_MAX_ROWS",
    "rounded",
    "write_csv",
    "write_outputs",
    "write_parquet",
    "write_summary",
]
