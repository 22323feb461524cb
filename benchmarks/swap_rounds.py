"""Where the sphere swap's decision time goes, by how each decision was found: writes
docs/results/swap-rounds.md.

Flies the sphere swap of ``bench_swarm.py`` with ``select_many`` (both cores), keeps the
arguments of every ``--every``-th call (shifted by one every other time, so that odd and even
steps are both kept), then replays each kept call one vehicle at a time
(``decide_range`` on one vehicle, one thread) and groups the decisions by their round: the
preferred velocity, a QP round (near / left / right), the fallbacks' grid, the least-bad fallback.

Each of ``--runs`` (``N[:STEPS][:fast]``: the swap's size, the steps flown, the fast preset)
is a section of the page.

    python benchmarks/swap_rounds.py [--runs 1000 10000:100 10000:100:fast] [--every 10]
        [--out docs/results/swap-rounds.md]
"""
from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from bench_swarm import scenario  # this folder's
from pages import RESULTS, command_line, machine_line, write_page

#: The runs of the page: the swap of 1,000 whole, the first 100 steps of 10,000 with the
#: default and the fast preset.
DEFAULT_RUNS = ("1000", "10000:100", "10000:100:fast")


def record(n: int, every: int, max_steps: int | None, fast: bool = False
           ) -> tuple[Any, list[tuple[tuple, dict]]]:
    """Fly the swap (``fast``: with the fast preset); the selector and every ``every``-th
    select_many call's arguments."""
    from vo3d_opt.selector import VelocitySelector
    from vo3d_opt.sim.deciders import SwarmSelect
    from vo3d_opt.sim.scenario import scenario_variant
    from vo3d_opt.sim.simulator import fly, scenario_selector

    calls: list[tuple[tuple, dict]] = []
    count = [0]
    real = VelocitySelector.select_many

    def kept(self, *args, **kwargs):
        # every ``every``-th call, one later every other time: odd and even steps alike (in the
        # swap most decisions keep the preferred velocity on one step and almost none on the
        # next, so a stride of 10 alone would see only one kind)
        j, r = divmod(count[0], every)
        if r == (j % 2 if every > 1 else 0):
            calls.append((args, dict(kwargs)))
        count[0] += 1
        return real(self, *args, **kwargs)

    sc = scenario("swap", n)
    if fast:
        sc = scenario_variant(sc, selector_options={**sc.selector_options, "preset": "fast"})
    sel, formulation, solver = scenario_selector(sc)
    step = SwarmSelect(sc, sel, formulation=formulation, solver=solver, max_neighbors=10, threads=2)
    VelocitySelector.select_many = kept
    try:
        fly(sc, step, progress=False, max_steps=max_steps)
    finally:
        VelocitySelector.select_many = real
    return sel, calls


def replay(sel: Any, calls: list[tuple[tuple, dict]]) -> dict[str, dict[str, float]]:
    """Per round: decisions, total ns, QPs solved."""
    from vo3d_opt import swarm
    from vo3d_opt.formulations.kernel import ROUND_NAMES
    from vo3d_opt.formulations.swarm import MANY_OUT_SIZE, decide_range

    out_stats: dict[str, dict[str, float]] = defaultdict(lambda: {"n": 0, "ns": 0, "solved": 0})
    for args, kwargs in calls:
        kwargs = {k: v for k, v in kwargs.items() if k != "threads"}
        inputs = swarm.SwarmInputs.checked(*args, **kwargs)
        sw = inputs.arrays()
        # each vehicle plans with the options of its own top speed, as select_many groups them
        cfg = [sel.options_for(float(v), inputs.dt, inputs.sensing_range).config
               for v in inputs.bounds[inputs.who, 1]]
        out = np.empty((sw.who.shape[0], MANY_OUT_SIZE))
        decide_range(sw, 0, 1, cfg[0], out)  # once before timing
        for d in range(sw.who.shape[0]):
            t0 = time.perf_counter_ns()
            decide_range(sw, d, d + 1, cfg[d], out)
            elapsed = time.perf_counter_ns() - t0
            st = out_stats[ROUND_NAMES[int(out[d, 5])]]
            st["n"] += 1
            st["ns"] += elapsed
            st["solved"] += int(out[d, 6])
    return out_stats


ROUNDS = ("preferred", "near", "left", "right", "sampled", "least_bad")


def summary(stats: dict[str, dict[str, float]]) -> list[dict[str, Any]]:
    """One record per round found (in ``ROUNDS`` order), then ``all``: decisions, their share,
    mean µs, share of the time, QPs solved per decision."""
    total_n = sum(s["n"] for s in stats.values())
    total_ns = sum(s["ns"] for s in stats.values())
    out = [{"round": name, "decisions": s["n"], "share": s["n"] / total_n,
            "mean_us": s["ns"] / s["n"] / 1e3, "time_share": s["ns"] / total_ns,
            "qps": s["solved"] / s["n"]}
           for name in ROUNDS if (s := stats.get(name))]
    out.append({"round": "all", "decisions": total_n, "share": 1.0,
                "mean_us": total_ns / total_n / 1e3, "time_share": 1.0,
                "qps": sum(s["solved"] for s in stats.values()) / total_n})
    return out


def section(run: dict[str, Any]) -> list[str]:
    """One run's heading, table and where its time goes."""
    flown = "whole run" if run["max_steps"] is None else f"first {run['max_steps']} steps"
    preset = ", preset fast" if run["fast"] else ""
    lines = [f"## Sphere swap{preset}, N = {run['n']}, {flown}", "",
             "| round | decisions | share of decisions | mean µs | share of time "
             "| QPs solved per decision |", "|---|---:|---:|---:|---:|---:|"]
    for r in run["rounds"]:
        share = "100%" if r["round"] == "all" else f"{r['share']:.1%}"
        time_share = "100%" if r["round"] == "all" else f"{r['time_share']:.1%}"
        lines.append(f"| {r['round']} | {r['decisions']} | {share} | {r['mean_us']:.1f} | "
                     f"{time_share} | {r['qps']:.1f} |")
    top = max((r for r in run["rounds"] if r["round"] != "all"), key=lambda r: r["time_share"])
    lines += ["", f"Most of the time goes to `{top['round']}`: {top['time_share']:.1%} of it for "
              f"{top['share']:.1%} of the decisions, {top['mean_us']:.1f} µs each against "
              f"{run['rounds'][-1]['mean_us']:.1f} on average.", ""]
    return lines


def page(runs: list[dict[str, Any]], every: int, machine: str, command: str) -> str:
    lines = ["# Where the sphere swap's decision time goes", "", machine, "",
             f"`{command}`: the sphere swap of `bench_swarm.py` flown with `select_many` (both "
             f"cores); one call in {every} (shifted by one every other time, so that odd and "
             "even steps are both kept) replayed one vehicle per compiled call on one "
             "thread, each decision counted by the round that found its velocity: the preferred "
             "velocity, a QP round (near / left / right), the fallbacks' grid, the least-bad "
             "fallback. In the swap's first steps the swarm can alternate between steps where "
             "most decisions keep the preferred velocity and steps where almost none do "
             "([swarms](swarm.md)), hence both kinds of step are replayed.", ""]
    for run in runs:
        lines += section(run)
    return "\n".join(lines)


def spec(text: str) -> dict[str, Any]:
    """``N[:STEPS][:fast]`` as a run: the swap's size, the steps flown (all when left out or
    empty) and whether it flies the fast preset."""
    parts = text.split(":")
    fast = parts[-1] == "fast"
    parts = parts[:-1] if fast else parts
    if not 1 <= len(parts) <= 2 or not all(p.isdigit() for p in parts if p):
        raise argparse.ArgumentTypeError(f"{text!r}: expected N[:STEPS][:fast]")
    steps = int(parts[1]) if len(parts) == 2 and parts[1] else None
    if int(parts[0]) < 2:
        raise argparse.ArgumentTypeError(f"{text!r}: N must be at least 2")
    return {"n": int(parts[0]), "max_steps": steps, "fast": fast}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=spec, nargs="+", metavar="N[:STEPS][:fast]",
                    default=[spec(x) for x in DEFAULT_RUNS],
                    help=f"swaps flown, one section each (default {' '.join(DEFAULT_RUNS)})")
    ap.add_argument("--every", type=int, default=10, help="keep every K-th select_many call")
    ap.add_argument("--out", type=Path, default=RESULTS / "swap-rounds.md")
    args = ap.parse_args(argv)
    if args.every < 1:
        ap.error("--every must be at least 1")
    runs = []
    for run in args.runs:
        sel, calls = record(run["n"], args.every, run["max_steps"], run["fast"])
        runs.append({**run, "rounds": summary(replay(sel, calls))})
        print(f"{run}: done", file=sys.stderr, flush=True)
    write_page(args.out, page(runs, args.every, machine_line(), command_line()))
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
