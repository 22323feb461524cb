"""Swarm scale: vo3d_opt's select_many (1 thread and every thread) against RVO2-3D's doStep.

``ours-noguard`` is ours on every thread with the ``closing_guard`` option, one of the
simulator's defaults (with reciprocal and pz_buffer), turned off: README, "Safety in
simulation". ``ours-coarse`` is ours on
every thread with avoidance planes every 30 degrees instead of 10 (``plane_step_deg``: 7 planes,
21 QPs instead of 57, and the fallbacks' grid on 7 planes: fewer velocities tried, the same
exact check of each). ``ours-nearest`` is ours on every thread with ``least_bad_escape`` off
(the rule of 0.1.0): the least-bad fallback, when every velocity enters a zone at once, takes
the one nearest the preferred velocity, not the one closing slowest on the zones the vehicle is
inside. ``ours-fast`` is ours on every thread with ``vo3d_opt.FAST_OPTIONS`` (``--fast`` on the
command line) added: planes every 45 degrees (5 planes, 15 QPs), tangent points among 12
generator samples instead of 36, the fallbacks' grid 8 headings by 3 speeds per plane.
``ours-swarm`` is the swarm preset (``--swarm`` on the command line, ``vo3d_opt.swarm_options``
in Python; ``ours-fast-h`` before 2026-11-26, evening): those and RVO2-3D's own time horizon
(``horizon``: the sensing range over twice the top speed, 6.875 s here; a velocity that would
meet a zone only later is allowed, as RVO2-3D allows it): ours by default, like the paper's VO,
has no horizon.

Every method flies the same scenarios in the same loop (``vo3d_opt.sim.simulator.fly``: the same
preferred velocities, dynamics and metrics), with the same dt (0.2 s), speeds (0-4 m/s),
sensing range (55 m) and neighbour count (``--max-neighbors``, default 10 for both):

* ``swap``: the sphere swap (``sphere_swap_scenario``: N agents on a sphere, each to its
  antipode, every path through the centre; r_pz 8 m);
* ``crossing``: the constant-density random crossing (``random_crossing_scenario``: one agent per
  64,000 m³ in a slab whose area grows with N, each flying 200 m in a random direction; r_pz
  10 m). The bundled ``random-crossing-1000`` is its N = 1000 instance.

"decide µs" is the time inside ``select_many()`` (ours: validation, k-d tree, neighbour lists
and the compiled decisions) or ``doStep()`` (RVO2-3D: its k-d tree, its linear programs and its
position update) divided by the agent-steps; "loop µs" the whole loop's wall time (preferred
velocities, dynamics, recording, RVO2's Python setters) per agent-step. Each run is its own
process, so "peak MB" is that run's peak resident memory (the run, its record and its metrics;
"(spilled)": the record was larger than ``SPILL_BYTES`` and lived in a temporary file,
``vo3d_opt.sim.spill``).
``--profile`` adds where ours spends its time on the first steps of each N = 1000 case
(``--profile-steps K``: the first K, default 100; 0: the whole run).

    python benchmarks/bench_swarm.py [--sizes 100 1000 10000] [--cases swap crossing]
        [--methods ours-1 ours-all ours-noguard ours-coarse ours-nearest ours-fast ours-swarm rvo2]
        [--max-neighbors 10]
        [--max-steps N=K ...]
        [--profile [--profile-steps K]]
        [--out benchmarks/results_swarm.md]

Writes the markdown table to ``--out`` as rows finish (one line of JSON per run also goes to
``--out`` with ``.jsonl``).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

METHODS = ("ours-1", "ours-all", "ours-noguard", "ours-coarse", "ours-nearest", "ours-fast", "ours-swarm",
           "rvo2")
#: Options each ``ours-*`` method adds to the simulator's (ours-1 and ours-all add none;
#: ours-fast adds ``vo3d_opt.FAST_OPTIONS``, ours-swarm those and ``horizon: sensing``:
#: ``extra_options``).
EXTRA_OPTIONS = {
    "ours-noguard": {"closing_guard": False},
    "ours-coarse": {"plane_step_deg": 30.0},
    "ours-nearest": {"least_bad_escape": False},
}


def extra_options(method: str) -> dict[str, Any] | None:
    """The selector options ``method`` adds to the simulator's (None: none), as ``-o`` would:
    ours-swarm's ``horizon: sensing`` is each scenario's sensing range over twice its top speed
    (RVO2-3D's ``timeHorizon`` on it), as ``vo3d run --swarm`` flies it. Imported here, not at
    the top: the parent process of the runs loads no vo3d_opt."""
    if method in ("ours-fast", "ours-swarm"):
        return {"preset": method.removeprefix("ours-")}
    return EXTRA_OPTIONS.get(method)


def resolved_options(method: str, sc: Any) -> dict[str, Any] | None:
    """``extra_options`` with ``horizon: sensing`` as the seconds it stood for on ``sc``."""
    extra = extra_options(method)
    if extra is not None and extra.get("preset") == "swarm":
        extra["horizon"] = sc.sensing_horizon  # what "sensing" resolves to
    return extra


def scenario(case: str, n: int):
    if case == "swap":
        from vo3d_opt.generators import sphere_swap_scenario

        return sphere_swap_scenario(n)
    from vo3d_opt.generators import random_crossing_scenario

    return random_crossing_scenario(n, seed=n)


def one_run(case: str, n: int, method: str, max_neighbors: int, max_steps: int | None) -> dict[str, Any]:
    """One (case, N, method) run in this process: its figures as a dict."""
    from vo3d_opt.baselines.rvo2 import RVO2Step, summarize_rvo2
    from vo3d_opt.sim.deciders import SwarmSelect
    from vo3d_opt.sim.metrics import decision_times_us, summarize
    from vo3d_opt.sim.scenario import scenario_variant
    from vo3d_opt.sim.simulator import fly, scenario_selector

    sc = scenario(case, n)
    if method == "rvo2":
        step: Any = RVO2Step(sc, max_neighbors=max_neighbors)
        threads = 1
    else:
        from vo3d_opt.swarm import cores

        threads = 1 if method == "ours-1" else cores()
        extra = extra_options(method)
        if extra is not None:  # the simulator's options plus the method's, as -o adds them
            sc = scenario_variant(sc, selector_options={**sc.selector_options, **extra})
        sel, formulation, solver = scenario_selector(sc)
        step = SwarmSelect(sc, sel, formulation=formulation, solver=solver, max_neighbors=max_neighbors,
                           threads=threads)
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    rec = fly(sc, step, progress=False, max_steps=max_steps)
    loop = time.perf_counter() - t0
    t0 = time.perf_counter()
    s = summarize_rvo2(rec) if method == "rvo2" else summarize(rec)
    metrics = time.perf_counter() - t0
    agent_steps = int(rec.decided.sum())
    decide = float(decision_times_us(rec).sum()) / 1e6
    return {
        "case": case, "n": n, "method": method, "threads": threads, "max_neighbors": max_neighbors,
        "steps": rec.steps, "n_steps": sc.n_steps, "agent_steps": agent_steps,
        "decide_us": decide / agent_steps * 1e6, "loop_us": loop / agent_steps * 1e6,
        "loop_s": loop, "metrics_s": metrics,
        "min_vehicle_distance": s["min_vehicle_distance"], "r_pz": float(sc.r_pz.max()),
        "pz_intrusions": s["pz_intrusions"], "collisions": s["collisions"], "reached": s["reached"],
        "all_reached": s["all_reached"], "arrival_time_max": s["arrival_time_max"],
        "altitude_violations": s["altitude_violations"], "fallbacks": s["fallbacks"],
        "status_counts": s["status_counts"],
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, "load_start": load,
        "record": "spilled" if rec.spill is not None else "memory",
        "options": resolved_options(method, sc),
        "load_end": os.getloadavg()[0],
    }


def profile_run(case: str, n: int, max_neighbors: int, steps: int | None) -> dict[str, Any]:
    """Where ours (1 thread) spends the first ``steps`` steps (None: the whole run): the input
    checks, the k-d tree and neighbour lists, the compiled decisions (building each vehicle's
    rows among them: they are no longer timed apart), the rest of the loop, the metrics."""
    from vo3d_opt import swarm
    from vo3d_opt.sim.deciders import SwarmSelect
    from vo3d_opt.swarm import many
    from vo3d_opt.sim.metrics import decision_times_us, summarize
    from vo3d_opt.sim.simulator import fly, scenario_selector

    spent = {"checks": 0.0, "tree": 0.0, "kernel": 0.0}

    def timed(key, fn):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            out = fn(*args, **kwargs)
            spent[key] += time.perf_counter() - t0
            return out
        return wrapper

    swarm.SwarmInputs.checked = classmethod(timed("checks", swarm.SwarmInputs.checked.__func__))
    swarm.SwarmInputs.arrays = timed("tree", swarm.SwarmInputs.arrays)
    many.decide_many = timed("kernel", many.decide_many)
    sc = scenario(case, n)
    sel, formulation, solver = scenario_selector(sc)
    step = SwarmSelect(sc, sel, max_neighbors=max_neighbors, threads=1)
    t0 = time.perf_counter()
    rec = fly(sc, step, progress=False, max_steps=steps)
    loop = time.perf_counter() - t0
    t0 = time.perf_counter()
    summarize(rec)
    metrics = time.perf_counter() - t0
    agent_steps = int(rec.decided.sum())
    decide = float(decision_times_us(rec).sum()) / 1e6
    us = {k: v / agent_steps * 1e6 for k, v in spent.items()}
    return {"case": case, "n": n, "steps": rec.steps, "agent_steps": agent_steps,
            "checks_us": us["checks"], "tree_us": us["tree"], "kernel_us": us["kernel"], "rows_us": None,
            "select_many_us": decide / agent_steps * 1e6,
            "loop_rest_us": (loop - decide) / agent_steps * 1e6,
            "metrics_us": metrics / agent_steps * 1e6, "load": os.getloadavg()[0]}


def _fmt(x: Any, spec: str = ".1f") -> str:
    return "—" if x is None else format(x, spec)


def _options_text(options: dict[str, Any] | None) -> str:
    """``{"a": 1, "b": 2.0}`` as ``a 1, b 2``."""
    return ", ".join(f"{k} {v:g}" for k, v in (options or {}).items())


def table_row(r: dict[str, Any]) -> str:
    name = {"ours-1": "vo3d_opt select_many, 1 thread", "ours-all": f"vo3d_opt select_many, {r['threads']} threads",
            "ours-noguard": f"vo3d_opt select_many, closing_guard off, {r['threads']} threads",
            "ours-coarse": f"vo3d_opt select_many, plane_step_deg "
                           f"{EXTRA_OPTIONS['ours-coarse']['plane_step_deg']:g}, {r['threads']} threads",
            "ours-nearest": f"vo3d_opt select_many, least_bad_escape off, {r['threads']} threads",
            "ours-fast": f"vo3d_opt select_many, FAST_OPTIONS ({_options_text(r.get('options'))}), "
                         f"{r['threads']} threads",
            "ours-swarm": f"vo3d_opt select_many, the swarm preset: FAST_OPTIONS and RVO2-3D's "
                          f"time horizon ({_options_text(r.get('options'))}), {r['threads']} threads",
            "rvo2": "RVO2-3D doStep, 1 thread"}[r["method"]]
    flown = "whole run" if r["steps"] < r["n_steps"] or r["all_reached"] else f"{r['steps']} steps (max_time)"
    if r.get("capped"):
        flown = f"first {r['steps']} steps"
    arrive = _fmt(r["arrival_time_max"]) if r["all_reached"] else "—"
    return (f"| {r['case']} | {r['n']} | {name} | {flown} | {_fmt(r['decide_us'])} | {_fmt(r['loop_us'])} "
            f"| {_fmt(r['min_vehicle_distance'], '.2f')} / {r['r_pz']:g} | {r['pz_intrusions']} | {r['collisions']} "
            f"| {r['reached']}/{r['n']} | {arrive} | {_fmt(r['fallbacks'], 'd') if r['fallbacks'] is not None else '—'} "
            f"| {r['metrics_s']:.1f} | {r['peak_mb']:.0f}{' (spilled)' if r.get('record') == 'spilled' else ''} "
            f"| {r['load_start']:.1f}–{r['load_end']:.1f} |")


HEADER = ("| case | N | method | flown | decide µs/agent-step | loop µs/agent-step | min distance / r_pz (m) "
          "| pz intrusions | collisions | arrived | last arrival (s) | fallbacks | metrics s | peak MB | load |\n"
          "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")


def _machine() -> str:
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent).stdout.strip()
    except OSError:
        commit = "?"
    from vo3d_opt.baselines.rvo2 import version

    return (f"{platform.platform()}; {os.cpu_count()} CPUs; Python {platform.python_version()}; compiled core "
            f"(C++, nanobind); rvo23d {version()}; commit {commit}; {time.strftime('%Y-%m-%d %H:%M')}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--cases", nargs="+", choices=("swap", "crossing"), default=["swap", "crossing"])
    ap.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    ap.add_argument("--max-neighbors", type=int, default=10)
    ap.add_argument("--max-steps", nargs="*", default=[], metavar="N=K", help="cap the runs of size N at K steps")
    ap.add_argument("--profile", action="store_true", help="also profile ours on the first steps at N = 1000")
    ap.add_argument("--profile-steps", type=int, default=100, metavar="K",
                    help="profile the first K steps (0: the whole run)")
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("results_swarm.md"))
    ap.add_argument("--one", nargs=3, metavar=("CASE", "N", "METHOD"), help=argparse.SUPPRESS)
    ap.add_argument("--profile-one", nargs=2, metavar=("CASE", "N"), help=argparse.SUPPRESS)
    ap.add_argument("--cap", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.profile_steps < 0:
        ap.error("--profile-steps must be 0 (the whole run) or more")
    if args.one:
        case, n, method = args.one
        row = one_run(case, int(n), method, args.max_neighbors, args.cap)
        row["capped"] = args.cap is not None and row["steps"] == args.cap
        print(json.dumps(row))
        return
    if args.profile_one:
        steps = args.profile_steps or None
        print(json.dumps(profile_run(args.profile_one[0], int(args.profile_one[1]), args.max_neighbors, steps)))
        return
    caps = {int(k): int(v) for k, v in (item.split("=") for item in args.max_steps)}
    lines = [f"# Swarm benchmark ({Path(__file__).name})", "", _machine(), "",
             f"max_neighbors {args.max_neighbors} for both methods; dt 0.2 s, 0-4 m/s, sensing 55 m.", "",
             HEADER]
    jsonl = args.out.with_suffix(".jsonl")
    jsonl.write_text("")

    def flush(extra: list[str] = ()) -> None:
        args.out.write_text("\n".join(lines + list(extra)) + "\n")

    flush()
    for case in args.cases:
        for n in args.sizes:
            for method in args.methods:
                cmd = [sys.executable, __file__, "--one", case, str(n), method, "--max-neighbors",
                       str(args.max_neighbors)] + (["--cap", str(caps[n])] if n in caps else [])
                res = subprocess.run(cmd, capture_output=True, text=True)
                if res.returncode != 0:
                    lines.append(f"| {case} | {n} | {method} | failed: {res.stderr.strip().splitlines()[-1:]} |")
                    flush()
                    continue
                row = json.loads(res.stdout.strip().splitlines()[-1])
                with jsonl.open("a") as fh:
                    fh.write(json.dumps(row) + "\n")
                lines.append(table_row(row))
                print(lines[-1], flush=True)
                flush()
    if args.profile:
        flown = f"first {args.profile_steps} steps" if args.profile_steps else "the whole run"
        lines += ["", f"Where ours spends its time (1 thread, {flown} at N = 1000, µs per agent-step):", "",
                  "| case | checks | k-d tree + neighbour lists | compiled decisions | of which row building "
                  "| select_many total | rest of the loop | metrics | load |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for case in args.cases:
            res = subprocess.run([sys.executable, __file__, "--profile-one", case, "1000", "--max-neighbors",
                                  str(args.max_neighbors), "--profile-steps", str(args.profile_steps)],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                lines.append(f"| {case} | failed: {res.stderr.strip().splitlines()[-1:]} |")
                continue
            p = json.loads(res.stdout.strip().splitlines()[-1])
            lines.append(f"| {case} | {p['checks_us']:.2f} | {p['tree_us']:.2f} | {p['kernel_us']:.2f} "
                         f"| {_fmt(p['rows_us'], '.2f')} | {p['select_many_us']:.2f} | {p['loop_rest_us']:.2f} "
                         f"| {p['metrics_us']:.2f} | {p['load']:.1f} |")
            print(lines[-1], flush=True)
            flush()
    flush()


if __name__ == "__main__":
    main()
