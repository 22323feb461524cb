"""Real-world conditions (dynamics, wind, noisy and late sensing) on the bundled scenarios:
writes docs/results/real-world.md.

Every bundled scenario under ideal kinematics (the reference for the cost columns), under
``first_order`` (tau 0.5 s and 1 s; and tau 1 s with the derived margins switched off, to show
what they buy), and under RotorPy's hummingbird without wind; the paper cases (1-4) under a
constant 3 m/s wind and under Dryden gusts (mean 3 m/s); the intruder scenario; sensing noise
0.5 m / 0.3 m/s with a 0.2 s latency on paper case 1; the paper's four cases and the flight
test under RotorPy (the flight test with the crazyflie, the vehicle the paper flew).
``random-crossing-1000`` flies under RotorPy's batched vehicles (``batched: true``: one torch
batch, fixed-step RK4 at 200 Hz), as does ``random-crossing-50`` beside its one-by-one run for
comparison; one period of the one-by-one model at N = 1000 is timed too (hours in all).

    .venv/bin/python benchmarks/bench_real_world.py [--quick]   # --quick: two scenarios only
    .venv/bin/python benchmarks/bench_real_world.py --swarm  # the swarm preset (vo3d run --swarm)

``--swarm``: every run with the swarm preset merged into its ``selector_options``
(``vo3d run --swarm``), into ``docs/results/real-world-swarm.md``.

Writes the whole page (``real_world_page.py`` renders it from the rows, as each run finishes)
and, at the end, its rows beside it (``.jsonl``); ``--render`` writes the page again from those
rows without flying anything.
"""
from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pages import RESULTS, command_line, machine_line, read_rows, write_page, write_rows
from real_world_page import page, record, row

from vo3d_opt.sim import run_scenario, summarize
from vo3d_opt.sim.dynamics import make_dynamics
from vo3d_opt.sim.scenario import (
    Scenario,
    bundled_files,
    load_scenario,
    scenario_variant,
)

OUT = RESULTS / "real-world.md"
SWARM_OUT = RESULTS / "real-world-swarm.md"
#: ``vo3d run --swarm``'s selector options.
SWARM = {"preset": "swarm"}
BIG = "random-crossing-1000"
PAPER = ["paper-case1-ten-uav-crossing", "paper-case2-two-uav-six-obstacles",
         "paper-case3-two-uav-two-cylinders", "paper-case3-three-spheres",
         "paper-case4-five-uav-six-square-obstacles"]
HUMMINGBIRD = {"dynamics": {"model": "rotorpy", "vehicle": "hummingbird"}}
BATCHED = {"dynamics": {"model": "rotorpy", "vehicle": "hummingbird", "batched": True}}
#: The margins switched off: no acceleration bound, no altitude or obstacle margin; the
#: pz_buffer of ideal kinematics (2 v_max dt) is set per scenario in :func:`variant`.
NO_MARGINS = {"acceleration": 0.0, "altitude_margin": 0.0, "obstacle_margin": 0.0}
#: RotorPy one by one is not run on these (its cost per period, measured, is reported
#: instead): hundreds of vehicles integrated one by one take hours (the crossing of 1,000 flies
#: batched).
ROTORPY_SKIPPED = ("random-crossing-1000", "rvo2-sphere-812")
#: The wind runs: the two-vehicle paper cases (RotorPy's cost, as above).
WIND = ["paper-case2-two-uav-six-obstacles", "paper-case3-two-uav-two-cylinders"]


@dataclass(frozen=True)
class Condition:
    name: str
    keys: dict[str, Any]
    scenarios: list[str]


def conditions(names: list[str]) -> list[Condition]:
    """The runs, cheapest first (the file is rewritten after each row, so a run cut short
    keeps what it measured): RotorPy's paper cases before its other scenarios, the 50- and
    1,000-agent crossings last."""
    small = [n for n in names if n != BIG]
    paper = [n for n in PAPER if n in names]
    flight = [n for n in ["paper-flight-test"] if n in names]
    rest = [n for n in small if n not in paper + flight + list(ROTORPY_SKIPPED)]
    noisy = {"position_noise": 0.5, "velocity_noise": 0.3, "latency": 0.2, "seed": 1}
    first_order = {tau: {"dynamics": {"model": "first_order", "tau": tau}} for tau in (0.5, 1.0)}
    big = [n for n in [BIG] if n in names]
    return [
        Condition("ideal (kinematic)", {}, small),
        Condition("first_order tau 0.5 s", first_order[0.5], small),
        Condition("first_order tau 1 s", first_order[1.0], small),
        Condition("first_order tau 1 s, margins off",
                  {**first_order[1.0], "safety": NO_MARGINS}, small),
        Condition("noise 0.5 m / 0.3 m/s, latency 0.2 s", {"sensing": noisy}, paper[:1]),
        Condition("noise + latency, first_order tau 0.5 s", {**first_order[0.5], "sensing": noisy},
                  paper[:1]),
        Condition("rotorpy hummingbird", HUMMINGBIRD, paper + flight),
        Condition("rotorpy crazyflie", {"dynamics": {"model": "rotorpy", "vehicle": "crazyflie"}},
                  flight),
        Condition("rotorpy hummingbird, wind 3 m/s",
                  {**HUMMINGBIRD, "wind": {"type": "constant", "velocity": [3.0, 0.0, 0.0]}},
                  [n for n in WIND if n in names]),
        Condition("rotorpy hummingbird, Dryden mean 3 m/s",
                  {**HUMMINGBIRD, "wind": {"type": "dryden", "velocity": [3.0, 0.0, 0.0]}},
                  [n for n in WIND if n in names]),
        Condition("rotorpy hummingbird", HUMMINGBIRD, rest),
        Condition("ideal (kinematic)", {}, big),
        Condition("first_order tau 1 s", first_order[1.0], big),
        Condition("rotorpy hummingbird, batched", BATCHED,
                  [n for n in ["random-crossing-50", BIG] if n in names]),
    ]


def variant(sc: Scenario, keys: dict[str, Any]) -> Scenario:
    """``sc`` under a condition's keys; "margins off" also takes ideal kinematics' pz_buffer."""
    if not keys:
        return sc
    if keys.get("safety") == NO_MARGINS:
        v_max = float(np.max(sc.max_speed))
        keys = {**keys, "safety": {**NO_MARGINS, "pz_buffer": 2.0 * v_max * sc.dt}}
    return scenario_variant(sc, **keys)


def run_one(sc: Scenario) -> tuple[dict[str, Any], float]:
    t0 = time.perf_counter()
    rec = run_scenario(sc, progress=False)
    wall = time.perf_counter() - t0
    s = summarize(rec)
    s["margins"] = rec.extra.get("margins", {})
    return s, wall


def rotorpy_step_cost(sc: Scenario, sample: int = 10) -> float:
    """Seconds per control period for all of ``sc``'s vehicles under RotorPy (the dynamics
    alone, in steady flight at 4 m/s), from one period of ``sample`` of them: RotorPy
    integrates each vehicle on its own, so the cost is linear in their number. (A 4 m/s
    command from hover costs several times more: its integrator takes tiny steps through the
    transient, which the simulator's rate limit avoids.)"""
    sample = min(sample, sc.n_agents)
    cruise = np.tile([4.0, 0.0, 0.0], (sample, 1))
    dyn = make_dynamics(HUMMINGBIRD["dynamics"])
    dyn.reset(sc.starts[:sample], cruise)
    dyn.step(cruise, sc.dt)  # imports and first calls
    t0 = time.perf_counter()
    dyn.step(cruise, sc.dt)
    return (time.perf_counter() - t0) / sample * sc.n_agents


def records(jobs: list[tuple[str, str, Scenario, bool]],
            results: dict[int, tuple[dict[str, Any], float]]) -> list[dict[str, Any]]:
    """The rows of the finished jobs, in job order; cost columns against the ideal run of the
    same scenario (when finished)."""
    ideal = {name: results[k][0] for k, (_, name, _, is_ideal) in enumerate(jobs)
             if is_ideal and k in results}
    return [record(cond, name, results[k][0], ideal.get(name), results[k][1])
            for k, (cond, name, _, _) in enumerate(jobs) if k in results]


def measure(names: list[str], swarm: bool, jobs_at_once: int,
            progress: Callable[[list[dict[str, Any]]], None]) -> list[dict[str, Any]]:
    """Every condition's runs (``progress`` called with the rows so far after each), then the
    cost of RotorPy one by one on the scenarios it does not fly."""
    base = {n: load_scenario(n) for n in names}
    if swarm:
        base = {n: scenario_variant(sc, selector_options=SWARM) for n, sc in base.items()}
    costs = [{"kind": "rotorpy_cost", "scenario": name, "agents": base[name].n_agents,
              "n_steps": base[name].n_steps, "dt": base[name].dt,
              "period_s": rotorpy_step_cost(base[name])}
             for name in ROTORPY_SKIPPED if name in base]
    jobs = [(cond.name, name, variant(base[name], cond.keys), not cond.keys)
            for cond in conditions(names) for name in cond.scenarios]
    results: dict[int, tuple[dict[str, Any], float]] = {}
    with ProcessPoolExecutor(max_workers=jobs_at_once) as pool:
        futures = {pool.submit(run_one, sc): k for k, (_, _, sc, _) in enumerate(jobs)}
        for fut in as_completed(futures):
            results[futures[fut]] = fut.result()
            progress(records(jobs, results) + costs)
    return records(jobs, results) + costs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two small scenarios, to try the script")
    ap.add_argument("--out", type=Path, default=None, help=f"default {OUT.name} ({SWARM_OUT.name} "
                    "with --swarm); its rows go beside it (.jsonl)")
    ap.add_argument("--swarm", action="store_true",
                    help="every run with the swarm preset (vo3d run --swarm)")
    ap.add_argument("--jobs", type=int, default=2, help="runs at once (processes)")
    ap.add_argument("--render", action="store_true",
                    help="write --out again from the rows beside it (runs nothing)")
    args = ap.parse_args()
    out = args.out or (SWARM_OUT if args.swarm else OUT)
    rows_file = out.with_suffix(".jsonl")
    if args.render:
        head, rows = read_rows(rows_file)
        write_page(out, page(rows, swarm=args.swarm, machine=head["machine"],
                             command=head["command"]))
        print(f"wrote {out} from {rows_file}", file=sys.stderr)
        return
    names = [f.stem for f in bundled_files()]
    if args.quick:
        names = ["paper-case3-two-uav-two-cylinders", "intruder-crossing-four"]
    command = command_line()

    def progress(rows: list[dict[str, Any]]) -> None:
        runs = [r for r in rows if r["kind"] == "run"]
        print(row(runs[-1]) if runs else "", file=sys.stderr, flush=True)
        write_page(out, page(rows, swarm=args.swarm, machine=machine_line(), command=command,
                             partial=True))

    rows = measure(names, args.swarm, args.jobs, progress)
    machine = machine_line()
    write_rows(rows_file, rows, machine=machine, command=command)
    write_page(out, page(rows, swarm=args.swarm, machine=machine, command=command))
    print(f"wrote {out} and {rows_file}", file=sys.stderr)


if __name__ == "__main__":
    main()
