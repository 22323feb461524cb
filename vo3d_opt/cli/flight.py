"""Flying a scenario for ``vo3d run`` and ``vo3d compare``, and printing its summary."""

from __future__ import annotations

import argparse
import logging
from typing import Any

from vo3d_opt.sim.metrics import CONTRACT_KEYS, summarize
from vo3d_opt.sim.scenario import Scenario
from vo3d_opt.sim.simulator import Simulator, flown_options

from .common import stdout_to_stderr

#: A run of at least this many agents with a formulation or backend that decides in Python
#: (not the compiled plane_qp on exact2d) is warned about: it takes a millisecond or more per
#: agent and step.
SLOW_SWARM = 200

log = logging.getLogger("vo3d_opt.cli")


def fly_and_summarize(
    sc: Scenario, sel: Any, formulation: str, solver: str, args: argparse.Namespace | None = None
) -> tuple[Any, dict[str, Any]]:
    """Fly the scenario (``args``: ``vo3d run``'s --threads, --max-neighbors, --spill,
    --spill-dir; None: the defaults); its record and summary."""
    log.info(
        "running %s (%s, %s) with %s / %s",
        sc.name,
        _count(sc.n_agents, "agent"),
        _count(len(sc.obstacles), "obstacle"),
        formulation,
        solver,
    )
    if sc.n_agents >= SLOW_SWARM and not getattr(sel, "compiled", True):
        log.warning(
            "%s / %s decides in Python, a millisecond or more per agent and step: %d agents "
            "will take long (plane_qp on exact2d, the default, is compiled)",
            formulation,
            solver,
            sc.n_agents,
        )
    flags = vars(args) if args is not None else {}
    progress = None if log.isEnabledFor(logging.INFO) else False  # -q: no progress bar either
    sim = Simulator(
        sc,
        sel,
        formulation=formulation,
        solver=solver,
        max_neighbors=flags.get("max_neighbors"),
        threads=flags.get("threads"),
    )
    with stdout_to_stderr():
        record = sim.run(
            progress=progress, spill=flags.get("spill"), spill_dir=flags.get("spill_dir")
        )
    summary = {**summarize(record), "selector_options": flown_options(sc)}
    log.info(
        "done: %d steps, %d/%d arrived, %.2f s wall time",
        summary["steps"],
        summary["reached"],
        summary["agents"],
        record.wall_time,
    )
    return record, summary


def fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}" if abs(value) < 1e4 else f"{value:.0f}"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {v}" for k, v in value.items()) or "-"
    return str(value)


def print_summary(summary: dict[str, Any]) -> None:
    keys = list(CONTRACT_KEYS) + [
        "status_counts",
        "selector_options",
        "obstacle_pz_intrusions",
        "starts_inside_pz",
        "arrival_time_max",
        "wall_time",
    ]
    width = max(len(k) for k in keys)
    for k in keys:
        if k in summary:
            print(f"{k:<{width}}  {fmt(summary[k])}")


def print_table(rows: list[dict[str, Any]], keys: list[str]) -> None:
    cells = [[fmt(r.get(k)) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[n]) for c in cells)) for n, k in enumerate(keys)]
    print("  ".join(k.ljust(w) for k, w in zip(keys, widths, strict=True)).rstrip())
    for c in cells:
        print("  ".join(v.ljust(w) for v, w in zip(c, widths, strict=True)).rstrip())


def _count(n: int, noun: str) -> str:
    """``1 agent``, ``2 agents``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"
