"""Encounters flown where they are called (a Dask worker, or this process).

:func:`run_encounter` regenerates encounter ``index`` of a family from (family, seed, index),
flies it with the :class:`Method` and returns one row: its parameters and its run
summary, or the error it raised. :func:`run_encounters` does the same for several, flying
those it can side by side (``vo3d_opt.sim.lockstep``), with the same rows. A row is a pure
function of (family, seed, index, method) but for the timing columns
(:data:`TIMING_COLUMNS`), which is why a sweep's results depend neither on how many workers
ran it nor on how its encounters were batched.
"""

from __future__ import annotations

import dataclasses
import json
import threading
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from vo3d_opt.generators import Family, get_family, make_encounter
from vo3d_opt.sim import lockstep
from vo3d_opt.sim.batch_select import decides_sensed_in_batches
from vo3d_opt.sim.deciders import NoAvoidance, decision_step
from vo3d_opt.sim.dynamics import Dynamics
from vo3d_opt.sim.metrics import pair_min_distances, summarize
from vo3d_opt.sim.record import DecisionStep, RunRecord, Snapshot, StepDecision
from vo3d_opt.sim.scenario import (
    Scenario,
    check_selector_options,
    scenario_from_dict,
    scenario_variant,
)
from vo3d_opt.sim.simulator import flown_options, fly, scenario_dynamics, scenario_selector

METHODS = ("vo3d", "rvo2", "none")
#: Columns that measure time or place, not behaviour: the only ones allowed to differ between
#: two runs of the same encounters.
TIMING_COLUMNS = (
    "decision_time_median_us",
    "decision_time_p99_us",
    "decision_time_max_us",
    "wall_time",
    "run_time",
    "worker",
    "compute_time_per_agent_step_us",  # RVO2-3D's own timing (baselines.summarize_rvo2)
)
#: Vehicles flown side by side at most (``vo3d_opt.sim.lockstep``): enough that the per-step
#: overhead is shared by dozens of encounters, few enough that the arrays stay small.
LOCKSTEP_AGENTS = 512
#: Vehicles in one RotorPy fleet at most (``vo3d_opt.sim.rotorpy_fleet``): a sweep task's
#: RotorPy encounters, each in a thread of its own with its record held until the last lands.
FLEET_AGENTS = 1024


@dataclass(frozen=True)
class Method:
    """How the encounters are flown: ``vo3d`` (the selector, with ``formulation`` / ``solver``
    as ``vo3d run`` takes them; None = the defaults), ``rvo2`` (RVO2-3D,
    ``vo3d_opt.baselines.run_rvo2``) or ``none`` (no avoidance: every agent flies straight to
    its goal, as ``avoids: false`` agents do; the unmitigated risk). ``selector_options``:
    (key, value) pairs merged into every encounter's ``selector_options`` (``vo3d`` only), e.g.
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


def without_avoidance(data: dict[str, Any]) -> dict[str, Any]:
    """A scenario dict with every agent ``avoids: false`` (what ``--method none`` flies)."""
    return {**data, "agents": [{**a, "avoids": False} for a in data["agents"]]}


def flown(sc: Scenario, method: Method) -> tuple[Scenario, DecisionStep, Any]:
    """What a ``vo3d`` or ``none`` method flies for scenario ``sc``: the scenario (with the
    method's selector options merged in, or nobody avoiding), its decision step (as
    ``Simulator`` builds it) and the ``selector_options`` its summary reports (None for
    ``none``)."""
    if method.name == "none":
        plain = without_avoidance(sc.model_dump(exclude_none=True))
        return scenario_from_dict(plain, sc.source), NoAvoidance(), None
    if method.selector_options:
        sc = scenario_variant(sc, selector_options=dict(method.selector_options))
    sel, formulation, solver = scenario_selector(sc, method.formulation, method.solver)
    return sc, decision_step(sc, sel, formulation=formulation, solver=solver), flown_options(sc)


def fly_encounter(sc: Scenario, method: Method) -> tuple[RunRecord, dict[str, Any]]:
    """Fly one scenario with the method; its record and its run summary (``vo3d run
    --json``'s), with ``selector_options``: the scenario's, the method's merged in (None for
    RVO2-3D and for ``none``).

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
    sc, step, options = flown(sc, method)
    record = fly(sc, step, progress=False)
    return record, {**summarize(record), "selector_options": options}


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


def _new_row(fam: Family, seed: int, index: int, method: Method) -> dict[str, Any]:
    return {
        "family": fam.name,
        "seed": int(seed),
        "index": int(index),
        "method": method.name,
        "error": None,
    }


def _drawn(row: dict[str, Any], fam: Family, seed: int, index: int) -> Scenario:
    """Draw encounter ``index`` into ``row`` (attempts, ``param_*``); its scenario."""
    enc = make_encounter(fam, seed, index)
    row["attempts"] = enc.attempts
    row.update({f"param_{k}": v for k, v in enc.params.items()})
    return enc.load()


def _summarised(row: dict[str, Any], record: RunRecord, summary: dict[str, Any]) -> None:
    for key in ("status_counts", "selector_options"):
        summary[key] = json.dumps(summary[key], sort_keys=True)
    row.update(summary)
    row["min_normalised_distance"] = normalised_min_distance(record)


def _closed(row: dict[str, Any], seconds: float) -> dict[str, Any]:
    row["run_time"] = seconds
    row["worker"] = _worker_name()
    return row


def run_encounter(
    family: str | Family, seed: int, index: int, method: Method = Method()
) -> dict[str, Any]:
    """Regenerate and fly encounter ``index``; one row: family, seed, index, method, attempts,
    ``param_*``, the summary's keys (``status_counts`` and ``selector_options`` as JSON text),
    ``min_normalised_distance``, ``error`` (None, or the exception in one line), ``run_time``
    and ``worker``. Never raises for a failing encounter: the error is the row's."""
    t0 = time.perf_counter()
    fam = get_family(family)
    row = _new_row(fam, seed, index, method)
    try:
        record, summary = fly_encounter(_drawn(row, fam, seed, index), method)
        _summarised(row, record, summary)
    except Exception as exc:  # noqa: BLE001 - one bad encounter must not stop the sweep
        row["error"] = error_line(exc)
    return _closed(row, time.perf_counter() - t0)


@dataclass
class _Waiting:
    """An encounter drawn and set up, waiting to be flown side by side with others."""

    row: dict[str, Any]
    sc: Scenario
    step: DecisionStep
    options: Any
    seconds: float


def run_encounters(
    family: str | Family, seed: int, indices: Sequence[int], method: Method = Method()
) -> list[dict[str, Any]]:
    """:func:`run_encounter` of each of ``indices``, the same rows (but the timing columns),
    in that order: those ``vo3d_opt.sim.lockstep`` can fly are flown side by side, a few
    hundred vehicles at a time, those with batched RotorPy vehicles in one fleet
    (:func:`in_fleet`), the others one by one."""
    fam = get_family(family)
    rows: list[dict[str, Any]] = []
    waiting: list[_Waiting] = []
    for index in indices:
        t0 = time.perf_counter()
        row = _new_row(fam, seed, index, method)
        rows.append(row)
        try:
            sc = _drawn(row, fam, seed, index)
            if method.name != "rvo2":
                sc, step, options = flown(sc, method)
                if lockstep.fits(sc, step) or in_fleet(sc):
                    waiting.append(_Waiting(row, sc, step, options, time.perf_counter() - t0))
                    continue
            _summarised(row, *fly_encounter(sc, method))
        except Exception as exc:  # noqa: BLE001 - one bad encounter must not stop the sweep
            row["error"] = error_line(exc)
        _closed(row, time.perf_counter() - t0)
    fleet = [w for w in waiting if in_fleet(w.sc)]
    for group in _fleet_groups(fleet):
        _fly_in_fleet(group, method)
    for group in _lockstep_groups([w for w in waiting if not in_fleet(w.sc)]):
        _fly_side_by_side(group, fam, method)
    return rows


def _lockstep_groups(waiting: list[_Waiting]) -> list[list[_Waiting]]:
    """The waiting encounters in groups of one ``dt``, one kind of decision step (from the
    true snapshot, or each run from its own sensor) and at most LOCKSTEP_AGENTS vehicles."""
    groups: list[list[_Waiting]] = []
    by_dt: dict[tuple[float, bool], list[_Waiting]] = {}
    for w in waiting:
        by_dt.setdefault((float(w.sc.dt), decides_sensed_in_batches(w.step)), []).append(w)
    for same in by_dt.values():
        group: list[_Waiting] = []
        for w in same:
            if group and sum(g.sc.n_agents for g in group) + w.sc.n_agents > LOCKSTEP_AGENTS:
                groups.append(group)
                group = []
            group.append(w)
        groups.append(group)
    return groups


def _fly_side_by_side(group: list[_Waiting], fam: Family, method: Method) -> None:
    """Fly a group with ``fly_together`` and fill in its rows; should that raise, each is
    flown alone (its own error, if any, in its own row)."""
    t0 = time.perf_counter()
    try:
        records = lockstep.fly_together([(w.sc, w.step) for w in group])
    except Exception:  # noqa: BLE001 - flown one by one below, each with its own outcome
        records = None
    share = (time.perf_counter() - t0) / len(group)
    for k, w in enumerate(group):
        t1 = time.perf_counter()
        try:
            if records is None:  # a step of its own: the batch's were used (sensors pushed)
                sc, step, _ = flown(w.sc, method)
                record = fly(sc, step, progress=False)
            else:
                record = records[k]
            _summarised(w.row, record, {**summarize(record), "selector_options": w.options})
        except Exception as exc:  # noqa: BLE001 - one bad encounter must not stop the sweep
            w.row["error"] = error_line(exc)
        spent = w.seconds + time.perf_counter() - t1 + (0.0 if records is None else share)
        _closed(w.row, spent)


def in_fleet(sc: Scenario) -> bool:
    """Whether ``sc``'s vehicles are batched RotorPy ones, which fly in a ``RotorPyFleet``
    with those of other encounters (``vo3d_opt.sim.rotorpy_fleet``: the same numbers)."""
    dyn = sc.vehicle_dynamics
    return dyn.model == "rotorpy" and bool(dyn.batched)


def _fleet_groups(waiting: list[_Waiting]) -> list[list[_Waiting]]:
    """The fleet's encounters in groups of one period, vehicle, sub-step rate and ramp, at
    most FLEET_AGENTS vehicles each (a thread and a record per encounter)."""
    groups: dict[tuple[Any, ...], list[list[_Waiting]]] = {}
    for w in waiting:
        dyn = w.sc.vehicle_dynamics
        key = (float(w.sc.dt), dyn.vehicle, dyn.substep_rate, dyn.ramped)
        same = groups.setdefault(key, [[]])
        if sum(g.sc.n_agents for g in same[-1]) + w.sc.n_agents > FLEET_AGENTS and same[-1]:
            same.append([])
        same[-1].append(w)
    return [g for same in groups.values() for g in same]


class _OneAtATime:
    """A decision step whose decisions take turns with those of the other runs of a fleet
    (one lock): some backends keep state per problem shape that two runs deciding at once
    would share (cvxpy's parameters, casadi's solver), and a sweep's worker is one core."""

    def __init__(self, step: DecisionStep, lock: threading.Lock) -> None:
        self._step, self._lock = step, lock

    def __getattr__(self, name: str) -> Any:
        return getattr(self._step, name)

    def decide(self, snap: Snapshot) -> StepDecision:
        with self._lock:
            return self._step.decide(snap)


def _fly_in_fleet(group: list[_Waiting], method: Method) -> None:
    """Fly a group with one ``RotorPyFleet`` (each encounter by ``fly`` in a thread of its
    own) and fill in its rows, each encounter's error in its own row: one whose run met a
    failed step of the fleet flies again alone."""
    from vo3d_opt.sim.rotorpy_fleet import FleetStepError

    t0 = time.perf_counter()
    try:
        outcomes: list[Any] = _fleet_outcomes(group)
    except Exception as exc:  # noqa: BLE001 - no fleet (e.g. no thread): each flies alone
        outcomes = [FleetStepError(error_line(exc))] * len(group)
    share = (time.perf_counter() - t0) / len(group)
    for w, outcome in zip(group, outcomes, strict=True):
        t1 = time.perf_counter()
        try:
            if isinstance(outcome, FleetStepError):
                sc, step, _ = flown(w.sc, method)
                outcome = fly(sc, step, progress=False)
            if isinstance(outcome, BaseException):
                raise outcome
            _summarised(w.row, outcome, {**summarize(outcome), "selector_options": w.options})
        except Exception as exc:  # noqa: BLE001 - one bad encounter must not stop the sweep
            w.row["error"] = error_line(exc)
        _closed(w.row, w.seconds + share + time.perf_counter() - t1)


def _fleet_outcomes(group: list[_Waiting]) -> list[RunRecord | Exception]:
    """Each encounter's record, or the exception its set-up or flight raised."""
    from vo3d_opt.sim.rotorpy_fleet import RotorPyFleet, import_torch

    with _TorchThreads.one(import_torch()):
        fleet, lock = RotorPyFleet(), threading.Lock()
        outcomes: list[Any] = [None] * len(group)
        models: list[Any] = []
        for k, w in enumerate(group):
            try:
                models.append(scenario_dynamics(w.sc, fleet=fleet))
            except Exception as exc:  # noqa: BLE001 - that encounter's outcome
                outcomes[k] = exc
                models.append(None)
        try:
            futures = _start_members(group, models, lock)
            for k, future in futures.items():
                try:
                    outcomes[k] = future.result()
                except Exception as exc:  # noqa: BLE001 - that encounter's outcome
                    outcomes[k] = exc
        except BaseException:  # interrupted (or failed): the runs end at their next period
            fleet.abort()
            raise
        return outcomes


def _start_members(
    group: list[_Waiting], models: list[Any], lock: threading.Lock
) -> dict[int, Future[RunRecord]]:
    """Each encounter with a model flying in a thread of its own: their futures by index."""
    futures = {}
    pool = ThreadPoolExecutor(max_workers=max(1, len(group)))
    try:
        for k, w in enumerate(group):
            if models[k] is not None:
                step = _OneAtATime(w.step, lock)
                futures[k] = pool.submit(_fly_member, w.sc, step, models[k])
    finally:  # a run that never started must not keep the others waiting
        for k, model in enumerate(models):
            if model is not None and k not in futures:
                model.leave()
        pool.shutdown(wait=False)  # its threads end with their runs
    return futures


class _TorchThreads:
    """torch on one thread while fleets fly (a sweep's worker is one core: torch's own pool
    would contend with the other workers); its count is restored when the last one lands."""

    lock = threading.Lock()
    fleets = 0  # flying in this process
    before = 1  # torch's thread count before the first

    @classmethod
    @contextmanager
    def one(cls, torch: Any) -> Iterator[None]:
        with cls.lock:
            if cls.fleets == 0:
                cls.before = torch.get_num_threads()
                torch.set_num_threads(1)
            cls.fleets += 1
        try:
            yield
        finally:
            with cls.lock:
                cls.fleets -= 1
                if cls.fleets == 0:
                    torch.set_num_threads(cls.before)


def _fly_member(sc: Scenario, step: DecisionStep, model: Dynamics) -> RunRecord:
    try:
        return fly(sc, step, dynamics=model, progress=False)
    finally:
        model.leave()  # type: ignore[attr-defined]  # a BatchedRotorPyDynamics


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
