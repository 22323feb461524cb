"""A sweep: encounters 0..N-1 of a family, flown on Dask (:func:`run_sweep`), and its summary.

Before the clock starts, every worker (and every worker that joins later, e.g. a restarted
one) flies a tiny encounter with the same method, so the modules and backends it needs are
loaded and no encounter's timing pays for it. ``wall_time`` is the time from the first
submission to the last row; ``setup_time`` the cluster's start and the warm-up before it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vo3d_opt.config import DEFAULT_PRESET
from vo3d_opt.extras import MissingExtra, check, needs
from vo3d_opt.generators import FAMILIES, Family, get_family, make_encounter
from vo3d_opt.sim.simulator import make_selector
from vo3d_opt.sweep.flight import DEFAULT_METHOD, METHODS, TIMING_COLUMNS, Method, error_line
from vo3d_opt.sweep.stats import aggregate
from vo3d_opt.sweep.store import FLUSH_SECONDS, PartStore, ResumeError, failed, rows_frame

with needs("sweep", "vo3d sweep"):
    from tqdm import tqdm

if TYPE_CHECKING:
    import pandas as pd

#: Dask's retries of a task whose worker died, for the local cluster (Dask's default is 3):
#: a task that kills its worker is reported after two deaths, not four.
ALLOWED_FAILURES = 1


class SweepError(ValueError):
    """A sweep that cannot start (bad option, unknown family/formulation/solver, unreachable
    scheduler): the message is one line naming the option."""


@dataclass
class SweepResult:
    """A finished sweep: one row per encounter (sorted by index) and the summary (see
    :func:`vo3d_opt.sweep.stats.aggregate`)."""

    family: Family
    seed: int
    method: Method
    rows: pd.DataFrame
    summary: dict[str, Any] = field(default_factory=dict)
    #: Where its rows were kept as they came (``out``), to be tidied once the outputs are written.
    store: PartStore | None = field(default=None, repr=False, compare=False)
    #: Encounters flown by this call (the others were found in ``out``).
    flown: int = 0


def check_method(family: Family, method: Method) -> tuple[str, str]:
    """(formulation, solver) names the summary reports; ``SweepError`` when the method cannot
    fly this family or names an unknown formulation or solver."""
    if method.name not in METHODS:
        raise SweepError(
            f"--method: unknown {method.name!r} (expected one of {', '.join(METHODS)})"
        )
    if method.name == "none":
        if method.formulation or method.solver or method.selector_options:
            raise SweepError(
                "--formulation/--solver/--preset/--selector-option: not used by --method none"
            )
        return "none", "none"
    if method.name == "rvo2":
        from vo3d_opt.baselines import rvo2

        if method.formulation or method.solver or method.selector_options:
            raise SweepError(
                "--formulation/--solver/--preset/--selector-option: not used by --method rvo2"
            )
        if not family.obstacle_free:
            ok = ", ".join(f.name for f in FAMILIES.values() if f.obstacle_free)
            raise SweepError(
                f"--method rvo2: family {family.name!r} has obstacles; RVO2-3D flies "
                f"obstacle-free families only ({ok})"
            )
        if not rvo2.available():
            raise SweepError(
                "--method rvo2: the rvo23d module is missing (pip install 'vo3d-opt[baselines]')"
            )
        return rvo2.FORMULATION, f"rvo23d {rvo2.version()}"
    try:  # the options are valid (Method checks them): whether the selector takes them
        options = {"sensing_range": 1.0, **dict(method.selector_options)}
        _, formulation, solver = make_selector(method.formulation, method.solver, options)
    except (ValueError, TypeError) as exc:
        form, solver = method.formulation or "default", method.solver or "default"
        what = f"formulation {form!r}, solver {solver!r}"
        raise SweepError(f"{what}: {' '.join(str(exc).split())}") from None
    return formulation, solver


#: The largest seed: the rows keep it in an int64 Parquet column.
MAX_SEED = 2**63 - 1
#: The most encounters of one sweep: their indices and rows are held in memory.
MAX_ENCOUNTERS = 10_000_000


def max_workers() -> int:
    """The most local worker processes: four per core, at least 8 (each is a Python process
    of its own; beyond the cores they only share them, and a huge count would exhaust memory
    before it flew anything)."""
    return max(8, 4 * (os.cpu_count() or 1))


def _check_counts(**values: int | None) -> None:
    lows = {"n": 1, "seed": 0, "workers": 1, "in_flight": 1, "batch": 1}
    highs = {"n": MAX_ENCOUNTERS, "seed": MAX_SEED, "workers": max_workers()}
    for key, value in values.items():
        if value is None and key in ("in_flight", "batch"):
            continue
        flag = f"--{key.replace('_', '-')}"
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lows[key]:
            raise SweepError(f"{flag}: must be an integer >= {lows[key]}, got {value!r}")
        if key in highs and value > highs[key]:
            raise SweepError(f"{flag}: must be at most {highs[key]:,}, got {value!r}")


def validate(
    family: str | Family,
    n: int,
    *,
    seed: int = 0,
    workers: int = 1,
    method: Method = DEFAULT_METHOD,
    in_flight: int | None = None,
    batch: int | None = None,
) -> tuple[Family, str, str]:
    """The family and the (formulation, solver) names of a sweep; ``SweepError`` naming the
    option when one is bad. Starts nothing."""
    try:
        fam = get_family(family)
    except ValueError as exc:
        raise SweepError(str(exc)) from None
    missing = fam.missing_keys()
    if missing:
        raise SweepError(
            f"family: {fam.name!r} needs the scenario keys {', '.join(missing)} "
            f"(real-world keys), which this build's scenario loader does not accept"
        )
    for extra in fam.extras:
        try:
            check(extra, f"family: {fam.name!r}")
        except MissingExtra as exc:
            raise SweepError(str(exc)) from None
    _check_counts(n=n, seed=seed, workers=workers, in_flight=in_flight, batch=batch)
    return (fam, *check_method(fam, method))


#: Encounters per task at most, for families flown side by side (``sim.lockstep``): enough to
#: share each step's overhead, few enough that tasks spread over the workers.
MAX_BATCH = 64


def default_batch(fam: Family, method: Method, count: int, threads: int) -> int:
    """Encounters per task: up to MAX_BATCH (about four tasks per worker thread) when the
    family's encounters fly side by side (``Family.batched``: in lockstep, or their RotorPy
    vehicles in one fleet; RVO2-3D flies one at a time),
    else one (an encounter of seconds or minutes is its own task: its row comes as soon as it
    lands)."""
    if method.name == "rvo2" or not fam.batched:
        return 1
    return max(1, min(MAX_BATCH, math.ceil(count / (4 * threads))))


def manifest(fam: Family, n: int, seed: int, method: Method, formulation: str, solver: str) -> dict:
    """What makes a sweep the same sweep (``sweep.json``, compared by ``--resume``); its
    ``draws`` names what the family draws in this version (:func:`draws_digest`)."""
    options = dict(method.selector_options)
    if method.name == "vo3d":
        options = {"preset": DEFAULT_PRESET, **options}
    return {
        "family": fam.name,
        "encounters": int(n),
        "seed": int(seed),
        "method": method.name,
        "formulation": formulation,
        "solver": solver,
        "selector_options": options,
        "draws": draws_digest(fam, seed, n),
    }


def draws_digest(fam: Family, seed: int, n: int) -> str:
    """SHA-256 (16 hex digits) of the scenarios of encounters 0, n/3, 2n/3 and n-1 of the
    family with ``seed``, their names and descriptions left out: a version of the family that
    draws other encounters or flies them under other conditions (its dynamics, wind, sensing) is
    another sweep, whose rows a resume must not mix in."""
    digest = hashlib.sha256()
    for i in sorted({0, n // 3, 2 * n // 3, max(n - 1, 0)}):
        try:
            drawn = make_encounter(fam, seed, i).scenario
        except RuntimeError as exc:  # a family that cannot be met: its row says so, as here
            digest.update(f"{i}: {exc}".encode())
            continue
        kept = {k: v for k, v in drawn.items() if k not in ("name", "description")}
        digest.update(json.dumps(kept, sort_keys=True, default=_not_json).encode())
    return digest.hexdigest()[:16]


def _not_json(value: Any) -> Any:
    raise TypeError(f"a drawn scenario holds {type(value).__name__}, not plain JSON")


def run_sweep(
    family: str | Family,
    n: int,
    *,
    seed: int = 0,
    workers: int = 1,
    scheduler: str | None = None,
    method: Method = DEFAULT_METHOD,
    in_flight: int | None = None,
    progress: bool = True,
    allowed_failures: int = ALLOWED_FAILURES,
    out: str | Path | None = None,
    resume: bool = False,
    overwrite: bool = False,
    batch: int | None = None,
    flush_seconds: float = FLUSH_SECONDS,
) -> SweepResult:
    """Fly encounters 0..n-1 of ``family`` with ``seed`` on a Dask cluster: a local one of
    ``workers`` processes (one thread each), or the existing one at ``scheduler``.

    ``in_flight``: tasks submitted at once (default 4 per worker thread, at least 8); ``batch``:
    encounters per task (default :func:`default_batch`); ``allowed_failures``: Dask's retries of
    a task whose worker died (local cluster only). ``out``: keep the rows in this directory as
    they come (``vo3d_opt.sweep.store``: a part at least every ``flush_seconds``); ``resume``:
    fly only the encounters missing there, or whose row there is an error; ``overwrite``:
    replace the sweep there, finished or not (without it, or ``resume``, a directory holding a
    sweep is refused).
    ``SweepError`` for bad options, before any cluster starts, or an unreachable scheduler;
    :class:`~vo3d_opt.extras.MissingExtra` without the ``[sweep]`` extra.
    """
    check("sweep", "vo3d sweep")
    fam, formulation, solver = validate(
        family, n, seed=seed, workers=workers, method=method, in_flight=in_flight, batch=batch
    )
    key = manifest(fam, n, seed, method, formulation, solver)
    store = None
    if out is not None:
        try:
            store = PartStore(out, key, resume, flush_seconds, overwrite=overwrite)
        except (ResumeError, OSError) as exc:
            raise SweepError(str(exc)) from None
    # an error row is flown again: a worker or scheduler lost is no result of the encounter's
    known = {} if store is None else {i: r for i, r in store.rows.items() if not failed(r)}
    missing = [i for i in range(n) if i not in known]
    fresh: list[dict[str, Any]] = []
    flying = {"wall": 0.0, "setup": 0.0, "threads": 0}
    try:
        if missing:
            fresh = _fly(
                fam,
                int(seed),
                missing,
                method,
                store,
                flying,
                options={
                    "workers": workers,
                    "scheduler": scheduler,
                    "in_flight": in_flight,
                    "batch": batch,
                    "progress": progress,
                    "allowed_failures": allowed_failures,
                },
            )
    finally:
        if store is not None:
            store.flush()  # whatever completed is on disk, interrupted or not
    df = rows_frame([*known.values(), *fresh])
    summary = aggregate(
        df,
        family=fam.name,
        seed=int(seed),
        method=method.name,
        formulation=formulation,
        solver=solver,
    )
    wall = flying["wall"]
    summary.update(
        {
            "selector_options": key["selector_options"],
            "wall_time": round(wall, 3),
            "setup_time": round(flying["setup"], 3),
            "encounters_per_second": round(len(missing) / wall, 4) if wall > 0 else None,
            "workers": flying["threads"],
            "scheduler": scheduler or "local",
        }
    )
    return SweepResult(
        family=fam,
        seed=int(seed),
        method=method,
        rows=df,
        summary=summary,
        store=store,
        flown=len(missing),
    )


def _fly(
    fam: Family,
    seed: int,
    missing: list[int],
    method: Method,
    store: PartStore | None,
    flying: dict[str, Any],
    options: dict[str, Any],
) -> list[dict[str, Any]]:
    """Fly ``missing`` on the cluster ``options`` describe; the rows (to ``store`` as they
    come); the wall time, set-up time and worker threads into ``flying``."""
    from vo3d_opt.sweep import cluster

    t_setup = time.perf_counter()
    try:
        with cluster.client_for(
            options["workers"], options["scheduler"], options["allowed_failures"]
        ) as client:
            try:
                client.register_plugin(cluster.WarmUp(method, fam.warm_keys))
            except Exception as exc:  # noqa: BLE001 - e.g. workers without vo3d_opt
                raise SweepError(f"warm-up failed on the workers: {error_line(exc)}") from None
            threads = int(sum(client.nthreads().values()))
            work = cluster.Work(
                fam=fam,
                seed=seed,
                method=method,
                indices=missing,
                batch=options["batch"] or default_batch(fam, method, len(missing), threads),
                in_flight=options["in_flight"] or max(8, 4 * threads),
            )
            flying["threads"] = threads
            flying["setup"] = time.perf_counter() - t_setup
            t0 = time.perf_counter()
            with tqdm(
                total=len(missing),
                desc=f"sweep {fam.name}",
                unit="enc",
                file=sys.stderr,
                disable=not options["progress"],
                smoothing=0.05,
            ) as bar:
                rows = cluster.submit_all(
                    client, work, bar, sink=None if store is None else store.add
                )
            flying["wall"] = time.perf_counter() - t0
    except cluster.ConnectError as exc:
        raise SweepError(f"--scheduler: {exc}") from None
    return rows


def rows_equal(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    """Whether two sweeps' rows agree in every column but :data:`TIMING_COLUMNS`."""
    cols = [c for c in a.columns if c not in TIMING_COLUMNS]
    if sorted(cols) != sorted(c for c in b.columns if c not in TIMING_COLUMNS):
        return False
    return a[cols].reset_index(drop=True).equals(b[cols].reset_index(drop=True))
