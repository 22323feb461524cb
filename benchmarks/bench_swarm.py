"""Swarm scale: vo3d_opt's select_many (1 thread and every thread) against RVO2-3D's doStep.

``ours-1`` and ``ours-all`` fly the ``safe`` preset (the default) on one thread and on every
thread; ``ours-paper``, ``ours-fast`` and ``ours-swarm`` the other presets on every thread
(``--preset NAME`` on the command line); ``ours-noguard``, ``ours-fine`` and
``ours-nearest`` the safe preset with ``closing_guard`` off, on the paper's 19 planes and 36
tangent samples with the sampled grid as the fallbacks' (10 degrees by 9 speeds), and with
``least_bad_escape`` off. The swarm preset plans with RVO2-3D's own time horizon (the sensing
range over twice the top speed): a velocity that would meet a zone only later is allowed, as
RVO2-3D allows it; the other presets, like the paper's VO, have no horizon.

Every method flies the same scenarios in the same loop (``vo3d_opt.sim.simulator.fly``: the same
preferred velocities, dynamics and metrics), with the same dt (0.2 s), speeds (0-4 m/s),
sensing range (55 m) and neighbour count (``--max-neighbors``, default 10 for both), except
``rvo2-sphere``:

* ``swap``: the sphere swap (``sphere_swap_scenario``: N agents on a sphere, each to its
  antipode, every path through the centre; r_pz 8 m);
* ``crossing``: the constant-density random crossing (``random_crossing_scenario``: one agent per
  64,000 m³ in a slab whose area grows with N, each flying 200 m in a random direction; r_pz
  10 m). The bundled ``random-crossing-1000`` is its N = 1000 instance;
* ``rvo2-sphere``: RVO2-3D's own ``Sphere`` example as its authors wrote it (the bundled
  ``rvo2-sphere-812``: 812 agents, dt 0.125 s, neighbour distance 15 m, 10 neighbours, radius
  1.5 m, top speed 2 m/s; RVO2-3D with its time horizon of 10 s); the size is always 812.

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
        [--methods ours-1 ours-all ours-noguard ours-fine ours-nearest ours-fast ours-swarm rvo2]
        [--max-neighbors 10]
        [--max-steps N=K ...]
        [--profile [--profile-steps K]]
        [--page swarm|rvo2-sphere] [--out docs/results/PAGE.md] [--append | --render]

Writes the whole page to ``--out`` as rows finish (``swarm_page.py`` renders it: the table and
every sentence with a figure in it come from the rows), and the rows beside it (``.jsonl``, a
header line with the machine and the command, then one line of JSON per run). ``--page``: the
layout, ``swarm`` (the default) or ``rvo2-sphere`` (the default when that case is the only one:
docs/results/rvo2-sphere.md). ``--append`` keeps the rows already there when they were measured
at this commit (a page names one commit), e.g. to add the whole N = 10,000 swap to a run that
capped it; ``--render`` writes the page again from the rows without running anything.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from pages import RESULTS, command_line, commit, machine_line, read_rows, write_page, write_rows
from swarm_page import PAGES, table_row

METHODS = ("ours-1", "ours-all", "ours-paper", "ours-noguard", "ours-fine", "ours-nearest",
           "ours-fast", "ours-swarm", "rvo2")
PRESET_METHODS = ("ours-paper", "ours-fast", "ours-swarm")
#: Options each ``ours-*`` method adds to the scenario's (ours-1 and ours-all add none; the
#: preset methods their preset: ``extra_options``).
EXTRA_OPTIONS = {
    "ours-noguard": {"closing_guard": False},
    "ours-fine": {"plane_step_deg": 10.0, "qp_samples": 36, "fallback_heading_step_deg": None,
                  "fallback_speed_levels": None},
    "ours-nearest": {"least_bad_escape": False},
}


def extra_options(method: str) -> dict[str, Any] | None:
    """The selector options ``method`` adds to the scenario's (None: none), as ``-o`` would:
    ours-swarm's ``horizon: sensing`` is each scenario's sensing range over twice its top speed
    (RVO2-3D's ``timeHorizon`` on it), as ``vo3d run --preset swarm`` flies it."""
    if method in PRESET_METHODS:
        return {"preset": method.removeprefix("ours-")}
    return EXTRA_OPTIONS.get(method)


def resolved_options(method: str, sc: Any) -> dict[str, Any] | None:
    """``extra_options`` with ``horizon: sensing`` as the seconds it stood for on ``sc``."""
    extra = extra_options(method)
    if extra is not None and extra.get("preset") == "swarm":
        extra["horizon"] = sc.sensing_horizon  # what "sensing" resolves to
    return extra


CASES = ("swap", "crossing", "rvo2-sphere")


def scenario(case: str, n: int):
    if case == "rvo2-sphere":
        from vo3d_opt.sim.scenario import load_scenario

        return load_scenario("rvo2-sphere-812")
    if case == "swap":
        from vo3d_opt.generators import sphere_swap_scenario

        return sphere_swap_scenario(n)
    from vo3d_opt.generators import random_crossing_scenario

    return random_crossing_scenario(n, seed=n)


def one_run(case: str, n: int, method: str, max_neighbors: int,
            max_steps: int | None) -> dict[str, Any]:
    """One (case, N, method) run in this process: its figures as a dict."""
    from vo3d_opt.baselines.rvo2 import RVO2Step, summarize_rvo2
    from vo3d_opt.sim.deciders import SwarmSelect
    from vo3d_opt.sim.metrics import decision_times_us, summarize
    from vo3d_opt.sim.scenario import scenario_variant
    from vo3d_opt.sim.simulator import fly, scenario_selector

    sc = scenario(case, n)
    if method == "rvo2":
        from vo3d_opt.generators.swarms import RVO2_SPHERE

        horizon = RVO2_SPHERE["time_horizon"] if case == "rvo2-sphere" else None
        step: Any = RVO2Step(sc, max_neighbors=max_neighbors, time_horizon=horizon)
        threads = 1
    else:
        from vo3d_opt.swarm import cores

        threads = 1 if method == "ours-1" else cores()
        extra = extra_options(method)
        if extra is not None:  # the simulator's options plus the method's, as -o adds them
            sc = scenario_variant(sc, selector_options={**sc.selector_options, **extra})
        sel, formulation, solver = scenario_selector(sc)
        step = SwarmSelect(sc, sel, formulation=formulation, solver=solver,
                           max_neighbors=max_neighbors, threads=threads)
    load = os.getloadavg()[0]
    t0, cpu0 = time.perf_counter(), time.process_time()
    rec = fly(sc, step, progress=False, max_steps=max_steps)
    loop, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    t0 = time.perf_counter()
    s = summarize_rvo2(rec) if method == "rvo2" else summarize(rec)
    metrics = time.perf_counter() - t0
    agent_steps = int(rec.decided.sum())
    decide = float(decision_times_us(rec).sum()) / 1e6
    return {
        "case": case, "n": n, "method": method, "threads": threads, "max_neighbors": max_neighbors,
        "steps": rec.steps, "n_steps": sc.n_steps, "agent_steps": agent_steps,
        "decide_us": decide / agent_steps * 1e6, "loop_us": loop / agent_steps * 1e6,
        "loop_s": loop, "metrics_s": metrics, "loop_cpu_us": cpu / agent_steps * 1e6,
        "min_vehicle_distance": s["min_vehicle_distance"], "r_pz": float(sc.r_pz.max()),
        "pz_intrusions": s["pz_intrusions"], "collisions": s["collisions"], "reached": s["reached"],
        "all_reached": s["all_reached"], "arrival_time_max": s["arrival_time_max"],
        "altitude_violations": s["altitude_violations"], "fallbacks": s["fallbacks"],
        "status_counts": s["status_counts"],
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, "load_start": load,
        "record": "spilled" if rec.spill is not None else "memory",
        "options": resolved_options(method, sc),
        "rvo2_horizon": step.horizon if method == "rvo2" else None,
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
            "checks_us": us["checks"], "tree_us": us["tree"], "kernel_us": us["kernel"],
            "rows_us": None,
            "select_many_us": decide / agent_steps * 1e6,
            "loop_rest_us": (loop - decide) / agent_steps * 1e6,
            "metrics_us": metrics / agent_steps * 1e6, "load": os.getloadavg()[0]}


def child(args: list[str]) -> dict[str, Any] | str:
    """This script run in a child process with ``args``: its JSON line, or its last error line."""
    res = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True)
    if res.returncode != 0:
        return " ".join(res.stderr.strip().splitlines()[-1:])
    return json.loads(res.stdout.strip().splitlines()[-1])


def kept(path: Path, append: bool) -> tuple[list[str], list[dict[str, Any]]]:
    """The commands and rows of an earlier run to keep (``--append``), refused unless that run
    measured the code of this commit (a page names one commit)."""
    if not append or not path.exists():
        return [], []
    head, rows = read_rows(path)
    if " + " in commit():  # uncommitted changes: no way to tell two states of them apart
        raise SystemExit("--append: the tree has uncommitted changes; commit them first")
    if head.get("commit") != commit():
        raise SystemExit(f"--append: the rows of {path} were measured at "
                         f"{head.get('commit', 'an unknown commit')}, not at {commit()}")
    earlier = head.get("command", [])
    return ([earlier] if isinstance(earlier, str) else earlier), rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--cases", nargs="+", choices=CASES, default=["swap", "crossing"])
    ap.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    ap.add_argument("--max-neighbors", type=int, default=10)
    ap.add_argument("--max-steps", nargs="*", default=[], metavar="N=K",
                    help="cap the runs of size N at K steps")
    ap.add_argument("--profile", action="store_true",
                    help="also profile ours on the first steps at N = 1000")
    ap.add_argument("--profile-steps", type=int, default=100, metavar="K",
                    help="profile the first K steps (0: the whole run)")
    ap.add_argument("--page", choices=sorted(PAGES), default=None,
                    help="the page's layout (default: rvo2-sphere when that case is the only one)")
    ap.add_argument("--out", type=Path, default=None, help="default docs/results/PAGE.md; its "
                    "rows go beside it (.jsonl)")
    ap.add_argument("--append", action="store_true",
                    help="keep the rows already beside --out (measured at this commit) and add "
                    "these")
    ap.add_argument("--render", action="store_true",
                    help="write --out again from the rows beside it (runs nothing)")
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
        case, n = args.profile_one
        print(json.dumps(profile_run(case, int(n), args.max_neighbors, steps)))
        return
    page_name = args.page or ("rvo2-sphere" if args.cases == ["rvo2-sphere"] else "swarm")
    out = args.out or RESULTS / f"{page_name}.md"
    rows_file = out.with_suffix(".jsonl")
    render = PAGES[page_name]
    if args.render:
        head, rows = read_rows(rows_file)
        write_page(out, render(rows, head["machine"], head["command"]))
        print(f"wrote {out} from {rows_file}", file=sys.stderr)
        return
    earlier, rows = kept(rows_file, args.append)
    command = [*earlier, command_line()]

    def flush() -> None:
        from vo3d_opt.baselines.rvo2 import version

        machine = machine_line("compiled core (C++, nanobind)", f"rvo23d {version()}")
        write_rows(rows_file, rows, machine=machine, command=command)
        write_page(out, render(rows, machine, command))

    caps = {int(k): int(v) for k, v in (item.split("=") for item in args.max_steps)}
    for case in args.cases:
        for n in [812] if case == "rvo2-sphere" else args.sizes:
            for method in args.methods:
                cap = ["--cap", str(caps[n])] if n in caps else []
                got = child(["--one", case, str(n), method, "--max-neighbors",
                             str(args.max_neighbors), *cap])
                failed = {"kind": "failed", "case": case, "n": n, "method": method, "error": got}
                rows.append(got if isinstance(got, dict) else failed)
                print(table_row(rows[-1]), file=sys.stderr, flush=True)
                flush()
    if args.profile:
        for case in args.cases:
            got = child(["--profile-one", case, "1000", "--max-neighbors", str(args.max_neighbors),
                         "--profile-steps", str(args.profile_steps)])
            failed = {"kind": "failed", "case": case, "n": 1000, "method": "profile", "error": got}
            rows.append({**got, "kind": "profile", "profile_steps": args.profile_steps}
                        if isinstance(got, dict) else failed)
            flush()
    flush()
    print(f"wrote {out} and {rows_file}", file=sys.stderr)


if __name__ == "__main__":
    main()
