"""A sweep: encounters 0..N-1 of a family, flown on Dask (:func:`run_sweep`), and its summary.

Before the clock starts, every worker (and every worker that joins later, e.g. a restarted
one) flies a tiny encounter with the same method, so the modules and backends it needs are
loaded and no encounter's timing pays for it. ``wall_time`` is the time from the first
submission to the last row; ``setup_time`` the cluster's start and the warm-up before it.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.generators import FAMILIES, Family, get_family
from vo3d_opt.sim.simulator import make_selector
from vo3d_opt.sweep.flight import DEFAULT_METHOD, METHODS, TIMING_COLUMNS, Method, error_line
from vo3d_opt.sweep.stats import aggregate

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
    """A finished sweep: one row per encounter (sorted by index) and the summary (contract §6
    keys and more, see :func:`vo3d_opt.sweep.stats.aggregate`)."""

    family: Family
    seed: int
    method: Method
    rows: pd.DataFrame
    summary: dict[str, Any] = field(default_factory=dict)


def check_method(family: Family, method: Method) -> tuple[str, str]:
    """(formulation, solver) names the summary reports; ``SweepError`` when the method cannot
    fly this family or names an unknown formulation or solver."""
    if method.name not in METHODS:
        raise SweepError(
            f"--method: unknown {method.name!r} (expected one of {', '.join(METHODS)})"
        )
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


def _check_counts(**values: int | None) -> None:
    lows = {"n": 1, "seed": 0, "workers": 1, "in_flight": 1}
    for key, value in values.items():
        if value is None and key == "in_flight":
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lows[key]:
            raise SweepError(
                f"--{key.replace('_', '-')}: must be an integer >= {lows[key]}, got {value!r}"
            )


def validate(
    family: str | Family,
    n: int,
    *,
    seed: int = 0,
    workers: int = 1,
    method: Method = DEFAULT_METHOD,
    in_flight: int | None = None,
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
            f"(contracts §5), which this build's scenario loader does not accept"
        )
    _check_counts(n=n, seed=seed, workers=workers, in_flight=in_flight)
    return (fam, *check_method(fam, method))


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
) -> SweepResult:
    """Fly encounters 0..n-1 of ``family`` with ``seed`` on a Dask cluster: a local one of
    ``workers`` processes (one thread each), or the existing one at ``scheduler``.

    ``in_flight``: tasks submitted at once (default 4 per worker thread, at least 8).
    ``allowed_failures``: Dask's retries of a task whose worker died (local cluster only).
    ``SweepError`` for bad options, before any cluster starts, or an unreachable scheduler.
    """
    import pandas as pd

    from vo3d_opt.sweep import cluster

    fam, formulation, solver = validate(
        family, n, seed=seed, workers=workers, method=method, in_flight=in_flight
    )
    t_setup = time.perf_counter()
    try:
        with cluster.client_for(workers, scheduler, allowed_failures) as client:
            try:
                client.register_plugin(cluster.WarmUp(method, fam.warm_keys))
            except Exception as exc:  # noqa: BLE001 - e.g. workers without vo3d_opt
                raise SweepError(f"warm-up failed on the workers: {error_line(exc)}") from None
            threads = int(sum(client.nthreads().values()))
            setup_time = time.perf_counter() - t_setup
            t0 = time.perf_counter()
            with tqdm(
                total=n,
                desc=f"sweep {fam.name}",
                unit="enc",
                file=sys.stderr,
                disable=not progress,
                smoothing=0.05,
            ) as bar:
                rows = cluster.submit_all(
                    client, fam, int(seed), n, method, in_flight or max(8, 4 * threads), bar
                )
            wall = time.perf_counter() - t0
    except cluster.ConnectError as exc:
        raise SweepError(f"--scheduler: {exc}") from None
    df = pd.DataFrame(rows).sort_values("index", kind="stable").reset_index(drop=True)
    summary = aggregate(
        df,
        family=fam.name,
        seed=int(seed),
        method=method.name,
        formulation=formulation,
        solver=solver,
    )
    summary.update(
        {
            "selector_options": dict(method.selector_options),
            "wall_time": round(wall, 3),
            "setup_time": round(setup_time, 3),
            "encounters_per_second": round(n / wall, 4) if wall > 0 else None,
            "workers": threads,
            "scheduler": scheduler or "local",
        }
    )
    return SweepResult(family=fam, seed=int(seed), method=method, rows=df, summary=summary)


def rows_equal(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    """Whether two sweeps' rows agree in every column but :data:`TIMING_COLUMNS`."""
    cols = [c for c in a.columns if c not in TIMING_COLUMNS]
    if sorted(cols) != sorted(c for c in b.columns if c not in TIMING_COLUMNS):
        return False
    return a[cols].reset_index(drop=True).equals(b[cols].reset_index(drop=True))
