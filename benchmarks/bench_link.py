"""``vo3d sitl`` against ``vo3d run`` on bundled scenarios (issue 42): the same safety figures
when every vehicle and every link is a process of its own talking MAVLink over UDP, and what
the link costs (set-point latency: newest own state message -> set-point sent, wall time;
``select()`` time per call inside a link).

For each scenario: ``vo3d run --json`` once, then ``vo3d sitl --json`` at ``--time-scale``
(default 1: real time, the figure that stands for a real vehicle's link) with the harness's
defaults (10 Hz decisions, vehicles at 50 Hz dynamics and 25 Hz telemetry). The machine's
cores are shared by every process of the run (a vehicle, a link per agent, the router).

    python benchmarks/bench_link.py [--time-scale K] [SCENARIO ...] > docs/results/link.md
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys

from vo3d_opt.cli import _fmt as fmt  # the table cells of vo3d run

SCENARIOS = ["paper-case1-ten-uav-crossing", "intruder-crossing-four",
             "paper-case3-two-uav-two-cylinders"]
SAFETY = ["agents", "reached", "time", "min_vehicle_distance", "min_obstacle_distance",
          "pz_intrusions", "obstacle_pz_intrusions", "collisions", "altitude_violations",
          "speed_violations", "fallbacks"]


def vo3d(*args: str) -> dict:
    res = subprocess.run([sys.executable, "-m", "vo3d_opt.cli", *args, "--json", "-q"],
                         capture_output=True, text=True, timeout=1800)
    if res.returncode != 0:
        raise SystemExit(f"vo3d {' '.join(args)} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenarios", nargs="*", default=SCENARIOS)
    ap.add_argument("--time-scale", default="1")
    args = ap.parse_args()
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    print(f"# {platform.machine()}, {os.cpu_count()} cores, CPython {platform.python_version()}, "
          f"{now}; vo3d sitl --time-scale {args.time_scale}\n")
    print("## Safety: vo3d run against vo3d sitl\n")
    print("| scenario | how | " + " | ".join(SAFETY) + " |")
    print("|---|---|" + "---|" * len(SAFETY))
    links = []
    for name in args.scenarios:
        run = vo3d("run", name)
        sitl = vo3d("sitl", name, "--time-scale", args.time_scale)
        for how, s in (("run", run), ("sitl", sitl)):
            print(f"| {name} | {how} | " + " | ".join(fmt(s.get(k)) for k in SAFETY) + " |")
        links.append((name, sitl))
    print("\n## The links (vo3d sitl)\n")
    keys = ["processes", "decisions", "setpoint_latency_median_ms", "setpoint_latency_p99_ms",
            "decision_time_median_us", "decision_time_p99_us", "rejected_total", "wall_time",
            "status_counts"]
    print("| scenario | " + " | ".join(keys) + " |")
    print("|---|" + "---|" * len(keys))
    for name, s in links:
        print(f"| {name} | " + " | ".join(fmt(s.get(k)) for k in keys) + " |")
    print("\nrun: `vo3d run`'s decision time is one `select_many` call's share per agent; "
          "sitl: one `select()` call inside a link process.")


if __name__ == "__main__":
    main()
