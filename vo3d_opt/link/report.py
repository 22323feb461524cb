"""What a link records of its ticks, and its JSON summary.

Summary keys (``vo3d link`` prints them as one JSON object on stdout when it stops):

* ``agent``, ``system_id``, ``autopilot``: who flew, and the autopilot's flavour;
* ``end``: why it stopped (``arrived``, ``max_time``, ``signal``, ``mode refused``,
  ``connection closed``, ...);
* ``arrived``: whether the own state was within the goal tolerance at the end;
* ``engaged_at``, ``time``: link time (s) when offboard / guided began, and at the end;
* ``decisions``: ``select()`` calls; ``status_counts``: ticks by status (the selector's, or
  ``hover: own state stale`` / ``hover: link lost``); ``fallbacks``: decisions whose status
  was not ``optimal``; ``setpoints``: set-points sent while flying (one per tick);
* ``setpoint_latency_median_ms``, ``setpoint_latency_p99_ms``: wall time from the arrival of
  the newest own state message to the set-point sent, over the ticks that decided (a hover on
  stale state comes from no state);
* ``decision_time_median_us``, ``decision_time_p99_us``: time per ``select()`` call;
* ``rejected``, ``rejected_total``: packets and reports refused, by reason (below);
* ``neighbors_late``, ``neighbors_dropped``, ``neighbors_passive``: per neighbour, ticks
  planned with its data late (older than ``--state-timeout``), times it was dropped (older
  than ``--neighbor-timeout``), ticks it was planned as non-cooperative (its autopilot not in
  offboard / guided, or its heartbeat old);
* ``formulation``, ``solver``, ``rate``, ``time_scale``, ``acks`` (``COMMAND_ACK`` received,
  by ``command:result``).

Rejection reasons: ``foreign_system`` (a system id outside the configured set),
``unsigned`` / ``bad_signature`` (signing on), ``bad_prefix`` (bytes that start no packet),
``bad_crc``, ``malformed``, ``truncated`` (a datagram that ended inside a packet),
``unknown_message``, ``non_finite``, ``impossible`` (outside the globe, faster than possible,
ADS-B without a position), ``implausible_jump`` (farther from the last report than the vehicle
could fly), ``no_origin`` (a geodetic report without ``--origin``).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from vo3d_opt.link.loop import Link


@dataclass
class LinkLog:
    """One row per tick flown: link time, status, the velocity sent (ENU), the set-point
    latency (s) and the ``select()`` time (s); both NaN when the link did not decide."""

    t: list[float] = field(default_factory=list)
    status: list[str] = field(default_factory=list)
    command: list[np.ndarray] = field(default_factory=list)
    latency: list[float] = field(default_factory=list)
    select_time: list[float] = field(default_factory=list)

    def tick(
        self, t: float, status: str, command: np.ndarray, latency: float, select_time: float
    ) -> None:
        self.t.append(t)
        self.status.append(status)
        self.command.append(np.asarray(command, dtype=float))
        self.latency.append(latency)
        self.select_time.append(select_time)

    def save(self, path: Path) -> None:
        """An ``.npz`` of the rows (``vo3d sitl`` reads it back with :func:`load_log`)."""
        np.savez(
            path,
            t=np.asarray(self.t, dtype=float),
            status=np.asarray(self.status, dtype=str),
            command=np.asarray(self.command, dtype=float).reshape(-1, 3),
            latency=np.asarray(self.latency, dtype=float),
            select_time=np.asarray(self.select_time, dtype=float),
        )


def load_log(path: Path) -> LinkLog:
    with np.load(path) as z:
        return LinkLog(
            t=z["t"].tolist(),
            status=[str(s) for s in z["status"]],
            command=list(z["command"]),
            latency=z["latency"].tolist(),
            select_time=z["select_time"].tolist(),
        )


def order_stats(values: Any, scale: float) -> tuple[float | None, float | None]:
    """(median, 99th percentile) of the finite ``values`` times ``scale``; None when empty."""
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)] * scale
    if not a.size:
        return None, None
    return float(np.median(a)), float(np.percentile(a, 99))


def decision_stats(log: LinkLog) -> dict[str, Any]:
    """``decisions``, ``status_counts``, ``fallbacks``, the set-point latency and the decision
    time of a log (or of several logs merged)."""
    counts = Counter(log.status)
    decided = np.isfinite(np.asarray(log.select_time, dtype=float))
    statuses = np.asarray(log.status, dtype=object)[decided] if log.status else []
    lat_mid, lat_99 = order_stats(log.latency, 1e3)
    dec_mid, dec_99 = order_stats(log.select_time, 1e6)
    return {
        "decisions": int(decided.sum()),
        "status_counts": dict(sorted(counts.items())),
        "fallbacks": int(sum(1 for s in statuses if s != "optimal")),
        "setpoints": len(log.t),
        "setpoint_latency_median_ms": lat_mid,
        "setpoint_latency_p99_ms": lat_99,
        "decision_time_median_us": dec_mid,
        "decision_time_p99_us": dec_99,
    }


def merge_logs(logs: list[LinkLog]) -> LinkLog:
    out = LinkLog()
    for one in logs:
        out.t += one.t
        out.status += one.status
        out.command += one.command
        out.latency += one.latency
        out.select_time += one.select_time
    return out


def link_summary(link: Link) -> dict[str, Any]:
    """The summary of the module docstring for a finished :class:`~vo3d_opt.link.loop.Link`."""
    o = link.o
    rejected = link.rejected + link.port.rejected
    own = link.own.position
    return {
        "agent": o.agent,
        "system_id": o.target_system,
        "autopilot": link.pilot.flavour,
        "end": link.stop_reason,
        "arrived": bool(own is not None and link.plan.arrived(own)),
        "engaged_at": link.engaged_at,
        "time": link.ended_at,
        **decision_stats(link.record),
        "rejected": dict(sorted(rejected.items())),
        "rejected_total": int(sum(rejected.values())),
        "neighbors_late": dict(sorted(link.tracks.late.items())),
        "neighbors_dropped": dict(sorted(link.tracks.drops.items())),
        "neighbors_passive": dict(sorted(link.tracks.passive.items())),
        "formulation": link.built.formulation,
        "solver": link.built.solver,
        "rate": o.rate,
        "time_scale": o.time_scale,
        "acks": dict(sorted(link.pilot.acks.items())),
    }
