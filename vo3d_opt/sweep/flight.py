"""One encounter, flown where it is called (a Dask worker, or this process).

:func:`run_encounter` regenerates encounter ``index`` of a family from (family, seed, index),
flies it with the :class:`Method` and returns one row: its parameters and its run
summary, or the error it raised. It is a pure function of its arguments but for the timing
columns (:data:`TIMING_COLUMNS`), which is why a sweep's results do not depend on how many
workers ran it.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from vo3d_opt.generators import Family, get_family, make_encounter
from vo3d_opt.sim.metrics import pair_min_distances, summarize
from vo3d_opt.sim.record import RunRecord
from vo3d_opt.sim.scenario import (
    Scenario,
    check_selector_options,
    scenario_from_dict,
    scenario_variant,
)
from vo3d_opt.sim.simulator import Simulator, flown_options, scenario_selector

METHODS = ("vo3d", "rvo2")
#: Columns that measure time or place, not behaviour: the only ones allowed to differ between
#: two runs of the same encounters.
TIMING_COLUMNS = (
    "decision_time_median_us",
    "decision_time_p99_us",
    "decision_time_max_us",
    "wall_time",
    "run_time",
    "worker",
)


@dataclass(frozen=True)
class Method:
    """How the encounters are flown: ``vo3d`` (the selector, with ``formulation`` / ``solver``
    as ``vo3d run`` takes them; None = the defaults) or ``rvo2`` (RVO2-3D,
    ``vo3d_opt.baselines.run_rvo2``). ``selector_options``: (key, value) pairs merged into
    every encounter's ``selector_options`` (``vo3d`` only), e.g.
    ``(("closing_guard", False),)``; kept validated, as a scenario file holds them, sorted by
    key, the last of a repeated key (``ValueError`` naming a bad one)."""

    name: str = "vo3d"
    formulation: str | None = None
    solver: str | None = None
    selector_options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        # One form per set of options: equal methods compare equal and every value is JSON
        # (the rows, summary.json and the failure scenarios write them).
        options = check_selector_options(dict(self.selector_options), "Method")
        object.__setattr__(self, "selector_options", tuple(options.items()))


#: The selector with its default formulation and solver.
DEFAULT_METHOD = Method()


def fly_encounter(sc: Scenario, method: Method) -> tuple[RunRecord, dict[str, Any]]:
    """Fly one scenario with the method; its record and its §3 summary, with
    ``selector_options``: the scenario's, the method's merged in (None for RVO2-3D).

    RVO2-3D keeps two agents ``radius_i + radius_j`` apart, so it flies every agent with the
    radius max(r_pz) / 2: each pair keeps at least its larger r_pz apart, which is what the
    metrics count (with per-agent r_pz / 2, a pair of unequal zones would be allowed closer than
    the larger one). The metrics judge the record against the encounter's own r_pz."""
    if method.name == "rvo2":
        from vo3d_opt.baselines import run_rvo2, summarize_rvo2

        r_pz = float(sc.r_pz.max())
        equal = sc.model_copy(
            update={"agents": [a.model_copy(update={"r_pz": r_pz}) for a in sc.agents]}
        )
        record = dataclasses.replace(run_rvo2(equal, progress=False), scenario=sc)
        return record, {**summarize_rvo2(record), "selector_options": None}
    if method.selector_options:
        sc = scenario_variant(sc, selector_options=dict(method.selector_options))
    sel, formulation, solver = scenario_selector(sc, method.formulation, method.solver)
    record = Simulator(sc, sel, formulation=formulation, solver=solver).run(progress=False)
    return record, {**summarize(record), "selector_options": flown_options(sc)}


def normalised_min_distance(record: RunRecord) -> float | None:
    """Smallest d / max(r_pz_i, r_pz_j) over vehicle pairs and the run (below 1: an intrusion)."""
    ii, jj, dmin = pair_min_distances(record.positions)
    if not dmin.size:
        return None
    r_pz = record.scenario.r_pz
    return float(np.min(dmin / np.maximum(r_pz[ii], r_pz[jj])))


def error_line(exc: BaseException) -> str:
    return " ".join(f"{type(exc).__name__}: {exc}".split())


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "local"


def run_encounter(
    family: str | Family, seed: int, index: int, method: Method = Method()
) -> dict[str, Any]:
    """Regenerate and fly encounter ``index``; one row: family, seed, index, method, attempts,
    ``param_*``, the summary's keys (``status_counts`` and ``selector_options`` as JSON text),
    ``min_normalised_distance``, ``error`` (None, or the exception in one line), ``run_time``
    and ``worker``. Never raises for a failing encounter: the error is the row's."""
    t0 = time.perf_counter()
    fam = get_family(family)
    row: dict[str, Any] = {
        "family": fam.name,
        "seed": int(seed),
        "index": int(index),
        "method": method.name,
        "error": None,
    }
    try:
        enc = make_encounter(fam, seed, index)
        row["attempts"] = enc.attempts
        row.update({f"param_{k}": v for k, v in enc.params.items()})
        record, summary = fly_encounter(enc.load(), method)
        for key in ("status_counts", "selector_options"):
            summary[key] = json.dumps(summary[key], sort_keys=True)
        row.update(summary)
        row["min_normalised_distance"] = normalised_min_distance(record)
    except Exception as exc:  # noqa: BLE001 - one bad encounter must not stop the sweep
        row["error"] = error_line(exc)
    row["run_time"] = time.perf_counter() - t0
    row["worker"] = _worker_name()
    return row


_WARM = {
    "name": "sweep-warm-up",
    "dt": 0.2,
    "max_time": 2.0,
    "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
    "defaults": {"r_pz": 5.0},
    "agents": [
        {"id": "a", "start": [-6.0, 0.0, 20.0], "goal": [6.0, 0.0, 20.0]},
        {"id": "b", "start": [6.0, 0.2, 20.0], "goal": [-6.0, 0.2, 20.0]},
    ],
}
_WARM_OBSTACLE = {"type": "cylinder", "center": [0.0, 12.0], "radius": 1.0, "height": 30.0}


def warm(method: Method, extra: dict[str, Any] | None = None) -> float:
    """Fly a 2 s two-UAV encounter (with a cylinder unless RVO2, plus the scenario keys
    ``extra``) so that every compiled kernel is loaded; the seconds it took."""
    t0 = time.perf_counter()
    data = dict(_WARM) if method.name == "rvo2" else {**_WARM, "obstacles": [_WARM_OBSTACLE]}
    data.update(extra or {})
    fly_encounter(scenario_from_dict(data, source="<warm-up>"), method)
    return time.perf_counter() - t0
