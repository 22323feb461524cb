"""A ``vo3d sitl`` run as a ``RunRecord``, judged by the simulator's own metrics.

The vehicles log their state at every dynamics step of their own clock (irregular instants);
between two steps a vehicle flies a straight line at constant velocity, so positions
interpolated linearly at any instant are its real trajectory. The record takes them on the
scenario's grid (``dt``) with ``round(dt * physics_rate)`` sub-steps per period as its
``samples`` (what the metrics judge, as for RotorPy runs), the command each vehicle flew at
each step, and each link's last tick within each step (its status and ``select()`` time).
``metrics.summarize`` gives the summary of ``vo3d run``; the decision figures
(``decisions``, ``status_counts``, ``fallbacks``, decision times) are then taken from every
tick of every link rather than one per step, and the link figures are added (set-point
latency, rejected packets, each link's own summary). ``preferred`` is the straight-to-goal
velocity (a link's detours are its own).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vo3d_opt.link.report import LinkLog, decision_stats, load_log, merge_logs
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.simulator import RunBuffers, RunRecord
from vo3d_opt.sim.traffic import goal_velocity

if TYPE_CHECKING:
    from vo3d_opt.link.sitl import Sitl

log = logging.getLogger("vo3d_opt.link.sitl")


@dataclass
class VehicleLog:
    t: np.ndarray
    p: np.ndarray
    v: np.ndarray
    u: np.ndarray

    @classmethod
    def load(cls, path: Path) -> VehicleLog:
        with np.load(path) as z:
            t, p, v, u = z["t"], z["p"], z["v"], z["u"]
        keep = np.concatenate([[True], np.diff(t) > 0])  # strictly increasing instants
        return cls(t[keep], p[keep], v[keep], u[keep])

    def positions(self, times: np.ndarray) -> np.ndarray:
        """(len(times), 3): linear between logged steps, held before the first and after the
        last."""
        return np.stack([np.interp(times, self.t, self.p[:, a]) for a in range(3)], axis=1)

    def commands(self, times: np.ndarray) -> np.ndarray:
        """The command flown at each instant: the last logged at or before it."""
        k = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.t) - 1)
        return self.u[k]


@dataclass
class SitlResult:
    record: RunRecord
    summary: dict[str, Any]
    interrupted: bool = False

    def write(self, out: Path) -> int:
        """``vo3d run --out``'s files in ``out``; 0, or 1 when writing failed."""
        from vo3d_opt.report import write_outputs

        try:
            for path in write_outputs(self.record, self.summary, out):
                log.info("wrote %s", path)
        except OSError as exc:
            log.error("--out %s: writing failed: %s", out, exc.strerror or exc)
            return 1
        return 0


def _ticks_per_step(one: LinkLog, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each step [t_k, t_k+1) (``times`` on the link's clock): the index of the link's
    last tick in it, and whether it had any."""
    t = np.asarray(one.t, dtype=float)
    last = np.searchsorted(t, times[1:], side="left") - 1
    first = np.searchsorted(t, times[:-1], side="left")
    return last, last >= first


def build_record(
    sitl: Sitl,
    span: tuple[float, float],
    wall: float,
    names: tuple[str, str],
    links: dict[str, LinkLog],
) -> RunRecord:
    """The :class:`RunRecord` of a finished run from the mission's start to its end (``span``,
    s of the run's clock; the record's time 0 is the start); ``names``: formulation, solver."""
    sc = sitl.o.scenario
    n, dt = sc.n_agents, float(sc.dt)
    start, end = span
    steps = max(1, math.ceil((end - start) / dt - 1e-9))
    per = max(1, round(dt * sitl.o.physics_rate))
    fine = start + np.arange(steps * per + 1) * (dt / per)
    logs = [VehicleLog.load(sitl.dir / f"vehicle-{name}.npz") for name in sc.ids]
    samples = np.stack([lg.positions(fine) for lg in logs], axis=1)  # (S, N, 3)
    sample_vel = np.zeros_like(samples)
    sample_vel[1:] = np.diff(samples, axis=0) / (dt / per)
    pos = samples[::per]
    times = start + np.arange(steps + 1) * dt
    buf = RunBuffers(steps, n)
    buf.pos[: steps + 1] = pos
    buf.vel[:steps] = np.diff(pos, axis=0) / dt
    buf.cmd[:steps] = np.stack([lg.commands(times[:-1]) for lg in logs], axis=1)
    for k in range(steps):
        buf.pref[k] = goal_velocity(pos[k], sc.goals, sc.cruise_speed, dt)
    _put_ticks(buf, sc.ids, links, times)
    near = np.linalg.norm(pos - sc.goals[None], axis=-1) <= sc.goal_tolerance
    buf.arrived[: steps + 1] = np.logical_or.accumulate(near, axis=0)
    if per > 1:
        for k in range(steps):
            rows = slice(k * per + 1, (k + 1) * per + 1)
            buf.put_samples(k, samples[rows], sample_vel[rows])
    return buf.record(sc, names[0], names[1], steps, wall, {"sitl": _extra(sitl)})


def _put_ticks(
    buf: RunBuffers, ids: list[str], links: dict[str, LinkLog], times: np.ndarray
) -> None:
    steps, n = len(times) - 1, len(ids)
    statuses = np.full((steps, n), "", dtype=object)
    decided = np.zeros((steps, n), dtype=bool)
    dtimes = np.full((steps, n), np.nan)
    for i, name in enumerate(ids):
        one = links.get(name)
        if one is None or not one.t:
            continue
        last, any_ = _ticks_per_step(one, times)
        decided[:, i] = any_
        idx = last[any_]
        statuses[any_, i] = np.asarray(one.status, dtype=object)[idx]
        dtimes[any_, i] = np.asarray(one.select_time, dtype=float)[idx]
    buf.decided[:steps] = decided
    for k in range(steps):
        buf.put_statuses(k, statuses[k], decided[k])
        buf.put_times(k, dtimes[k], dtimes[k], decided[k])


def _extra(sitl: Sitl) -> dict[str, Any]:
    o = sitl.o
    return {
        "rate": o.rate,
        "time_scale": o.time_scale,
        "autopilot": o.autopilot,
        "physics_rate": o.physics_rate,
        "telemetry_rate": o.telemetry_rate,
        "signed": o.signing_key is not None,
    }


def _names(sitl: Sitl, summaries: dict[str, Any]) -> tuple[str, str]:
    for s in summaries.values():
        if s.get("formulation"):
            return str(s["formulation"]), str(s["solver"])
    from vo3d_opt.sim.simulator import scenario_selector

    _, formulation, solver = scenario_selector(sitl.o.scenario)
    return formulation, solver


def build_result(sitl: Sitl, span: tuple[float, float], wall: float) -> SitlResult:
    """The record and the summary of a finished run (the module docstring)."""
    summaries = sitl.link_summaries()
    links = {
        name: load_log(sitl.dir / f"link-{name}.npz")
        for name in sitl.links
        if (sitl.dir / f"link-{name}.npz").is_file()
    }
    record = build_record(sitl, span, wall, _names(sitl, summaries), links)
    summary = summarize(record)
    ticks = decision_stats(merge_logs(list(links.values())))
    times = np.concatenate(
        [np.zeros(0)] + [np.asarray(lg.select_time, float) for lg in links.values()]
    )
    times = times[np.isfinite(times)]
    rejected: Counter[str] = Counter()
    for s in summaries.values():
        rejected.update(s.get("rejected", {}))
    summary.update(
        {k: ticks[k] for k in ("decisions", "status_counts", "fallbacks")},
        decision_time_median_us=ticks["decision_time_median_us"],
        decision_time_p99_us=ticks["decision_time_p99_us"],
        decision_time_max_us=float(times.max() * 1e6) if times.size else None,
        selector_options=dict(sitl.o.scenario.selector_options),
        setpoints=ticks["setpoints"],
        setpoint_latency_median_ms=ticks["setpoint_latency_median_ms"],
        setpoint_latency_p99_ms=ticks["setpoint_latency_p99_ms"],
        rejected=dict(sorted(rejected.items())),
        rejected_total=int(sum(rejected.values())),
        processes=len(sitl.procs),
        **_extra(sitl),
        faults=dict(sitl.injected),
        links=summaries,
    )
    return SitlResult(record, summary)
