"""Issue 12's conditions on the bundled scenarios: writes docs/results/real-world.md.

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
(``FAST_OPTIONS`` and ``horizon: sensing``), into ``docs/results/real-world-swarm.md``.
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vo3d_opt.sim import run_scenario, summarize
from vo3d_opt.sim.dynamics import make_dynamics
from vo3d_opt.sim.scenario import (
    Scenario,
    bundled_files,
    load_scenario,
    scenario_variant,
)

#: The docs' results pages, which these benchmarks write.
RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"

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
#: instead): a thousand vehicles integrated one by one take hours; they fly batched.
ROTORPY_SKIPPED = ("random-crossing-1000",)
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


def _f(x: Any, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def row(cond: str, name: str, s: dict[str, Any], ideal: dict[str, Any] | None, wall: float) -> str:
    m = s["margins"]
    path = (s["path_length_ratio"] / ideal["path_length_ratio"]
            if ideal and s["path_length_ratio"] and ideal["path_length_ratio"] else None)
    arrive = (s["arrival_time_max"] / ideal["arrival_time_max"]
              if ideal and s["arrival_time_max"] and ideal["arrival_time_max"] else None)
    accel = "–" if m.get("acceleration") is None else f"{m['acceleration']:.3g}"
    return (f"| {cond} | {name} | {s['reached']}/{s['agents']} | {s['collisions']} | "
            f"{s['pz_intrusions']} | {s['obstacle_pz_intrusions']} | {s['altitude_violations']} | "
            f"{s['speed_violations']} | "
            f"{_f(s['min_vehicle_distance'])} | {_f(s['min_obstacle_distance'])} | "
            f"{_f(path, 3)} | {_f(arrive, 3)} | {s['fallbacks']} | {_f(m.get('pz_buffer'))} | "
            f"{accel} | {_f(m.get('altitude_margin'))} | {wall:.1f} |")


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


HEADER = ("| condition | scenario | arrived | collisions | pz intrusions | "
          "obstacle pz intrusions | "
          "altitude violations | speed violations | min vehicle dist. m | min obstacle dist. m | "
          "path vs ideal | arrival vs ideal | fallbacks | pz_buffer m | acceleration m/s² | "
          "altitude margin m | wall s |\n|" + "---|" * 17)


def _rows(jobs: list[tuple[str, str, Scenario, bool]],
          results: dict[int, tuple[dict[str, Any], float]]) -> list[str]:
    """The table rows of the finished jobs, in job order; cost columns against the ideal run
    of the same scenario (when finished)."""
    ideal = {name: results[k][0] for k, (_, name, _, is_ideal) in enumerate(jobs)
             if is_ideal and k in results}
    return [row(cond, name, *results[k][:1], ideal.get(name), results[k][1])
            for k, (cond, name, _, _) in enumerate(jobs) if k in results]


def condensed(path: Path) -> str:
    """One row per condition of a results file: the summary table of docs/results/real-world.md (sums over its scenarios,
    the smallest distances, the median cost)."""
    rows = [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in path.read_text(encoding="utf-8").splitlines()
            if line.startswith("| ") and not line.startswith("| condition")]
    out = ["| condition | scenarios | arrived | collisions | pz intrusions | altitude violations | "
           "speed violations | min vehicle dist. m | min obstacle dist. m | "
           "path vs ideal (median) | arrival vs ideal (median) |", "|" + "---|" * 11]
    for cond in dict.fromkeys(r[0] for r in rows):
        rs = [r for r in rows if r[0] == cond]
        got = [tuple(map(int, r[2].split("/"))) for r in rs]

        def least(col: int, rs: list[list[str]] = rs) -> str:
            vals = [float(r[col]) for r in rs if r[col] != "–"]
            return f"{min(vals):.2f}" if vals else "–"

        def median(col: int, rs: list[list[str]] = rs) -> str:
            vals = [float(r[col]) for r in rs if r[col] != "–"]
            return f"{np.median(vals):.3f}" if vals else "–"

        out.append(f"| {cond} | {len(rs)} | {sum(a for a, _ in got)}/{sum(b for _, b in got)} | "
                   f"{sum(int(r[3]) for r in rs)} | {sum(int(r[4]) for r in rs)} | "
                   f"{sum(int(r[6]) for r in rs)} | {sum(int(r[7]) for r in rs)} | {least(8)} | "
                   f"{least(9)} | {median(10)} | {median(11)} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two small scenarios, to try the script")
    ap.add_argument("--out", type=Path, default=None, help=f"default {OUT.name} ({SWARM_OUT.name} "
                    "with --swarm)")
    ap.add_argument("--swarm", action="store_true",
                    help="every run with the swarm preset (vo3d run --swarm)")
    ap.add_argument("--jobs", type=int, default=2, help="runs at once (processes)")
    ap.add_argument("--readme", action="store_true",
                    help="print the condensed table of --out, one row per condition (runs nothing)")
    args = ap.parse_args()
    if args.out is None:
        args.out = SWARM_OUT if args.swarm else OUT
    if args.readme:
        print(condensed(args.out))
        return
    names = [f.stem for f in bundled_files()]
    if args.quick:
        names = ["paper-case3-two-uav-two-cylinders", "intruder-crossing-four"]
    base = {n: load_scenario(n) for n in names}
    if args.swarm:
        base = {n: scenario_variant(sc, selector_options=SWARM) for n, sc in base.items()}
    head = [f"# Real-world conditions (issue 12)\n\n{platform.machine()}, CPython "
            f"{platform.python_version()}, {os.cpu_count()} cores shared with other jobs, "
            f"{datetime.date.today().isoformat()}. `benchmarks/bench_real_world.py"
            f"{' --swarm' if args.swarm else ''}`.\n",
            "Cost columns: path length ratio and latest arrival against the same scenario under "
            "ideal kinematics (1.000 = no cost). Margins: what the simulator derived "
            "(`vo3d_opt/sim/safety.py`, `formulations/real_world.md`); \"margins off\": no "
            "acceleration bound, no altitude or obstacle margin, the pz_buffer of ideal "
            "kinematics (2 v_max dt).\n", HEADER]
    lines: list[str] = []
    tail: list[str] = []
    for name in (n for n in ROTORPY_SKIPPED if n in base):
        cost = rotorpy_step_cost(base[name])
        tail.append(f"\n`{name}` under RotorPy one by one: not run. One 0.2 s period of its "
                    f"{base[name].n_agents} hummingbirds in steady flight costs {cost:.1f} s of "
                    f"RotorPy alone here "
                    f"(each vehicle integrated on its own), so its up to {base[name].n_steps} "
                    f"periods would take up to {cost * base[name].n_steps / 3600:.1f} h. It "
                    f"flies batched instead (the last rows).")
    jobs = [(cond.name, name, variant(base[name], cond.keys), not cond.keys)
            for cond in conditions(names) for name in cond.scenarios]
    results: dict[int, tuple[dict[str, Any], float]] = {}
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = {pool.submit(run_one, sc): k for k, (_, _, sc, _) in enumerate(jobs)}
        for fut in as_completed(futures):
            results[futures[fut]] = fut.result()
            lines = _rows(jobs, results)
            print(lines[-1] if lines else "", file=sys.stderr, flush=True)
            args.out.write_text("\n".join(head + lines + tail) + "\n\n(partial: still running)\n",
                                encoding="utf-8")
    lines = _rows(jobs, results)
    args.out.write_text("\n".join(head + lines + tail) + "\n", encoding="utf-8")
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
