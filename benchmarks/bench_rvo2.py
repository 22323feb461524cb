"""RVO2-3D versus vo3d_opt (plane_qp, default QP solver) on sphere swaps of N agents.

N agents on a Fibonacci sphere whose radius grows with N (neighbouring starts 2 r_pz apart,
r_pz 8 m, 4 m/s, dt 0.2 s) each fly to their antipode (``sphere_swap_scenario``). Both methods
fly the same scenario with the same preferred-velocity rule and are judged by the same metrics
(vo3d_opt.sim.metrics); see vo3d_opt/baselines/rvo2.py for the RVO2 parameters (radius
r_pz / 2, neighborDist = sensing range, all neighbours, time horizon range / 2 v_max).

A whole N = 1000 run would take vo3d_opt half an hour or more here, so by default it flies only
the first K = 25 steps for N = 1000 (``--steps``); RVO2-3D then flies the same window (a like
for like row) and also the whole run. RVO2-3D with every neighbour takes about 10 minutes for the
whole N = 1000 run, so that run uses RVO2's customary maxNeighbors 10 (``--rvo2-full-neighbors``).

    python benchmarks/bench_rvo2.py [--max-n 1000] [--steps 1000=25]

Prints a markdown table; "compute" is the total time inside select() (ours) or doStep()
(RVO2, shared among the agents that moved) divided by the agent-steps.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings

import numpy as np

from vo3d_opt.baselines.rvo2 import (
    run_rvo2,
    sphere_swap_scenario,
    summarize_record,
    summarize_rvo2,
    version,
)
from vo3d_opt.sim.simulator import run_scenario

DEFAULT_STEPS = {1000: 25}


def _parse_steps(items: list[str]) -> dict[int, int]:
    out: dict[int, int] = {}
    for item in items:
        try:
            n, k = item.split("=")
            out[int(n)] = int(k)
        except ValueError:
            raise SystemExit(f"--steps: expected N=K, got {item!r}") from None
    return out


def _fmt(x, spec: str = ".3f") -> str:
    return "—" if x is None else format(x, spec)


def row(method: str, window: str, s: dict, wall: float) -> str:
    n = s["agents"]
    arrive = _fmt(s["arrival_time_max"], ".1f") if s["all_reached"] else "—"
    return (f"| {n} | {method} | {window} | {_fmt(s['min_vehicle_distance'], '.4f')} | {s['pz_intrusions']} "
            f"| {s['collisions']} | {s['altitude_violations']} | {s['reached']}/{n} | {arrive} "
            f"| {_fmt(s['compute_time_per_agent_step_us'], '.0f')} "
            f"| {_fmt(s['decision_time_median_us'], '.0f')} | {wall:.1f} |")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-n", type=int, default=1000, help="largest swarm (10, 100, 1000)")
    ap.add_argument("--sizes", type=int, nargs="*", default=[10, 100, 1000])
    ap.add_argument("--steps", nargs="*", default=[], metavar="N=K",
                    help="cap vo3d_opt (and the like-for-like RVO2 row) at K steps for size N; "
                         "K=0 for the whole run (default: 1000=25)")
    ap.add_argument("--solver", default=None, help="QP solver for plane_qp (default: the selector's)")
    ap.add_argument("--rvo2-full-neighbors", type=int, default=10,
                    help="maxNeighbors of RVO2's whole run when N > 100 (default 10)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    caps = dict(DEFAULT_STEPS)
    caps.update(_parse_steps(args.steps))
    sizes = [n for n in args.sizes if n <= args.max_n]

    print(f"# {platform.platform()}; {platform.processor() or platform.machine()}; "
          f"Python {platform.python_version()}; rvo23d {version()}; {time.strftime('%Y-%m-%d')}")
    print("| N | method | simulated | min distance (m) | pz intrusions | collisions | altitude viol. "
          "| arrived | last arrival (s) | compute µs/agent-step | median µs | wall s |")
    print("|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    notes = []
    for n in sizes:
        sc = sphere_swap_scenario(n)
        cap = caps.get(n) or None
        window = "whole run" if cap is None else f"first {cap} steps"
        r_pz = float(sc.r_pz[0])
        radius = float(np.linalg.norm(sc.starts[0] - sc.goals[0]) / 2)
        notes.append(f"N={n}: sphere radius {radius:.1f} m, r_pz {r_pz:g} m, max_time {sc.max_time:g} s "
                     f"({sc.n_steps} steps)")

        t0 = time.perf_counter()
        rec = run_scenario(sc, formulation="plane_qp", solver=args.solver, max_steps=cap,
                           progress=False)
        s = summarize_record(rec)
        print(row(f"vo3d_opt plane_qp ({rec.solver})", window, s, time.perf_counter() - t0), flush=True)
        if s["fallbacks"]:
            notes.append(f"N={n}: vo3d_opt statuses {s['status_counts']}")

        t0 = time.perf_counter()
        rec = run_rvo2(sc, max_steps=cap)
        s = summarize_rvo2(rec)
        print(row("RVO2-3D (all neighbours)", window, s, time.perf_counter() - t0), flush=True)

        if cap is not None:
            full_nb = None if n <= 100 else args.rvo2_full_neighbors
            t0 = time.perf_counter()
            rec = run_rvo2(sc, max_neighbors=full_nb)
            s = summarize_rvo2(rec)
            label = "RVO2-3D (all neighbours)" if full_nb is None else f"RVO2-3D (maxNeighbors {full_nb})"
            print(row(label, "whole run", s, time.perf_counter() - t0), flush=True)
        rvo_note = (f"RVO2-3D: agent radius r_pz/2 = {r_pz / 2:g} m, neighborDist "
                    f"{sc.sensing.vehicle_range:g} m, time horizon {rec.extra['time_horizon']:g} s; "
                    "it has no altitude limits (the altitude column counts any sample outside them)")
        if rvo_note not in notes:
            notes.append(rvo_note)
    print()
    for line in notes:
        if line:
            print(f"- {line}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
