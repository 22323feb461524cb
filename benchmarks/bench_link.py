"""``vo3d sitl`` against ``vo3d run`` on bundled scenarios: the same safety figures
when every vehicle and every link is a process of its own talking MAVLink over UDP, and what
the link costs (set-point latency: newest own state message -> set-point sent, wall time;
``select()`` time per call inside a link).

For each scenario: ``vo3d run --json`` once, then ``vo3d sitl --json`` at ``--time-scale``
(default 1: real time, the figure that stands for a real vehicle's link) with the harness's
defaults (10 Hz decisions, vehicles at 50 Hz dynamics and 25 Hz telemetry). The machine's
cores are shared by every process of the run (a vehicle, a link per agent, the router).

    python benchmarks/bench_link.py [--time-scale K] [--out docs/results/link.md] [SCENARIO ...]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from pages import RESULTS, command_line, machine_line, write_page

from vo3d_opt.cli.flight import fmt  # the table cells of vo3d run

SCENARIOS = ["paper-case1-ten-uav-crossing", "intruder-crossing-four",
             "paper-case3-two-uav-two-cylinders"]
SAFETY = ["agents", "reached", "time", "min_vehicle_distance", "min_obstacle_distance",
          "pz_intrusions", "obstacle_pz_intrusions", "collisions", "altitude_violations",
          "speed_violations", "fallbacks"]
LINK = ["processes", "decisions", "setpoint_latency_median_ms", "setpoint_latency_p99_ms",
        "decision_time_median_us", "decision_time_p99_us", "rejected_total", "wall_time",
        "status_counts"]
#: The safety figures that must not be worse over the link: counts of events.
EVENTS = ["pz_intrusions", "obstacle_pz_intrusions", "collisions", "altitude_violations",
          "speed_violations"]


def vo3d(*args: str) -> dict:
    res = subprocess.run([sys.executable, "-m", "vo3d_opt.cli", *args, "--json", "-q"],
                         capture_output=True, text=True, timeout=1800)
    if res.returncode != 0:
        raise SystemExit(f"vo3d {' '.join(args)} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout)


def harness() -> str:
    """The rates ``vo3d sitl`` flies at by default (``SitlOptions``)."""
    from dataclasses import fields

    from vo3d_opt.link.sitl import SitlOptions

    default = {f.name: f.default for f in fields(SitlOptions)}
    return (f"{default['rate']:g} Hz decisions, vehicles at {default['physics_rate']:g} Hz "
            f"dynamics and {default['telemetry_rate']:g} Hz telemetry")


def findings(runs: dict[str, dict[str, dict[str, Any]]]) -> list[str]:
    """What the two tables say: whether sitl kept every event count of run, and the range of
    the links' set-point latency."""
    more = {name: [k for k in EVENTS if (s["sitl"].get(k) or 0) > (s["run"].get(k) or 0)]
            for name, s in runs.items()}
    worse = [f"`{name}` ({', '.join(keys)})" for name, keys in more.items() if keys]
    arrived = all(s["sitl"].get("reached") == s["sitl"].get("agents") for s in runs.values())
    medians = [s["sitl"]["setpoint_latency_median_ms"] for s in runs.values()
               if s["sitl"].get("setpoint_latency_median_ms") is not None]
    out = [("Over the link no event count is higher than in `vo3d run`" if not worse else
            "Over the link these scenarios count more events than in `vo3d run`: "
            + ", ".join(worse)) + ("; every vehicle arrives." if arrived else
                                   "; not every vehicle arrives.")]
    if medians:
        spread = f"{min(medians):.1f}" if len(medians) == 1 else \
            f"{min(medians):.1f}-{max(medians):.1f}"
        out.append(f"Median set-point latency {spread} ms.")
    return [" ".join(out)]


def page(runs: dict[str, dict[str, dict[str, Any]]], time_scale: str, machine: str,
         command: str) -> str:
    """The whole page from the summaries of ``vo3d run`` and ``vo3d sitl`` per scenario."""
    lines = ["# vo3d sitl against vo3d run", "", machine, "",
             f"`{command}`: bundled scenarios "
             f"flown by `vo3d run` and by `vo3d sitl --time-scale {time_scale}` (every vehicle and "
             f"link its own process over UDP; the harness's defaults: {harness()}; the machine's "
             "cores shared by every process of the run).", "",
             "## Safety: vo3d run against vo3d sitl", "",
             "| scenario | how | " + " | ".join(SAFETY) + " |", "|---|---|" + "---|" * len(SAFETY)]
    for name, s in runs.items():
        for how in ("run", "sitl"):
            lines.append(f"| {name} | {how} | " + " | ".join(fmt(s[how].get(k)) for k in SAFETY)
                         + " |")
    lines += ["", "## The links (vo3d sitl)", "",
              "| scenario | " + " | ".join(LINK) + " |", "|---|" + "---|" * len(LINK)]
    for name, s in runs.items():
        lines.append(f"| {name} | " + " | ".join(fmt(s["sitl"].get(k)) for k in LINK) + " |")
    lines += ["", "run: `vo3d run`'s decision time is one `select_many` call's share per agent; "
              "sitl: one `select()` call inside a link process. A run over real sockets and real "
              "clocks is not repeatable to the decision.", "", *findings(runs)]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", default=SCENARIOS)
    ap.add_argument("--time-scale", default="1")
    ap.add_argument("--out", type=Path, default=RESULTS / "link.md")
    args = ap.parse_args()
    runs = {}
    for name in args.scenarios:
        runs[name] = {"run": vo3d("run", name),
                      "sitl": vo3d("sitl", name, "--time-scale", args.time_scale)}
        print(f"{name}: done", file=sys.stderr, flush=True)
    write_page(args.out, page(runs, args.time_scale, machine_line(), command_line()))
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
