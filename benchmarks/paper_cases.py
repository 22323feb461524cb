"""Our figures for the paper's cases beside the paper's own (docs/results/paper-cases.md).

Runs every scenarios/paper-*.yaml under the given formulations and prints a markdown table:
closest vehicle-vehicle and vehicle-obstacle distances, safety counts, and time per decision;
then case 3's VO pyramid against the three-sphere workaround, beside the paper's MATLAB
0.3035 s vs 1.4530 s per iteration; then the simulator's safety options (reciprocal, pz_buffer,
closing_guard, least_bad_escape) against the paper's selection as published (``--safety-only``:
that table alone, which has no timing column).

    python benchmarks/paper_cases.py [--formulations plane_qp sampled] [--safety-only]
"""
from __future__ import annotations

import argparse
import platform
import time
import warnings

from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import bundled_files
from vo3d_opt.sim.scenario import load_scenario
from vo3d_opt.sim.safety import derive_margins
from vo3d_opt.sim.simulator import make_selector, run_scenario

#: What the paper reports (section 5 and 6): closest vehicle and obstacle distances, m.
PAPER = {
    "paper-case1-ten-uav-crossing": ("9.893", "–"),
    "paper-case2-two-uav-six-obstacles": ("12.28", "5.522"),
    "paper-case3-two-uav-two-cylinders": ("–", "–"),
    "paper-case3-three-spheres": ("–", "–"),
    "paper-case4-five-uav-six-square-obstacles": ("10.13", "7.931"),
    "paper-flight-test": ("–", "0.3521"),
}


def fmt(x: float | None, digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--formulations", nargs="+", default=["plane_qp", "sampled"])
    ap.add_argument("--safety-only", action="store_true", help="the safety options' table alone")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    print(f"# {platform.machine()}, Python {platform.python_version()}, {time.strftime('%Y-%m-%d')}")
    if not args.safety_only:
        cases(args.formulations)
    safety()


def cases(formulations: list[str]) -> None:
    """The paper's cases under each formulation, then case 3's pyramid against the spheres."""
    print("| case | formulation | min vehicle dist. m (paper) | min obstacle dist. m (paper) | "
          "pz intrusions | collisions | arrived | median µs / decision |")
    print("|---|---|---|---|---:|---:|---|---:|")
    rows = {}
    for path in bundled_files():
        if not path.stem.startswith("paper-"):
            continue
        for form in formulations:
            s = summarize(run_scenario(path, formulation=form, progress=False))
            rows[(path.stem, form)] = s
            pv, po = PAPER[path.stem]
            print(f"| {path.stem} | {form} | {fmt(s['min_vehicle_distance'])} ({pv}) | "
                  f"{fmt(s['min_obstacle_distance'])} ({po}) | {s['pz_intrusions']} | {s['collisions']} | "
                  f"{s['reached']}/{s['agents']} | {s['decision_time_median_us']:.0f} |", flush=True)
    print()
    print("| case 3 | formulation | median µs / decision | p99 µs | paper (MATLAB, s / iteration) |")
    print("|---|---|---:|---:|---|")
    for stem, paper in (("paper-case3-two-uav-two-cylinders", "0.3035"), ("paper-case3-three-spheres", "1.4530")):
        for form in formulations:
            s = rows[(stem, form)]
            print(f"| {stem} | {form} | {s['decision_time_median_us']:.0f} | {s['decision_time_p99_us']:.0f} | {paper} |")
    print()


def safety() -> None:
    """The simulator's safety options against the paper's selection as published (plane_qp);
    the rows without reciprocity also with ``least_bad_escape`` off (the rule of 0.1.0)."""
    print("| scenario (plane_qp) | reciprocal | pz_buffer m | closing_guard | least_bad_escape "
          "| min vehicle dist. m | pz intrusions | collisions | fallbacks |")
    print("|---|---|---:|---|---|---:|---:|---:|---:|")
    for stem in ("paper-case1-ten-uav-crossing", "sphere-swap-16"):
        sc = load_scenario(next(p for p in bundled_files() if p.stem == stem))
        buf = derive_margins(sc).pz_buffer
        for rec, b, guard, escape in ((False, 0.0, False, True), (False, 0.0, False, False),
                                      (True, 0.0, False, True), (False, buf, False, True),
                                      (False, buf, False, False), (True, buf, False, True),
                                      (False, 0.0, True, True), (True, buf, True, True)):
            opts = {"preset": "paper", "reciprocal": rec, "pz_buffer": b, "closing_guard": guard,
                    "least_bad_escape": escape}
            sel, _, _ = make_selector("plane_qp", None, opts)
            s = summarize(run_scenario(sc, sel, progress=False))
            print(f"| {stem} | {rec} | {b:g} | {guard} | {escape} | {fmt(s['min_vehicle_distance'])} "
                  f"| {s['pz_intrusions']} | {s['collisions']} | {s['fallbacks']} |", flush=True)


if __name__ == "__main__":
    main()
