"""Where the sphere swap's decision time goes, by how each decision was found (README, Swarms).

Flies the sphere swap of ``bench_swarm.py`` with ``select_many`` (both cores), keeps the
arguments of every ``--every``-th call (shifted by one every other time, so that odd and even
steps are both kept), then replays each kept call one vehicle at a time
(``decide_range`` on one vehicle, one thread) and groups the decisions by their round: the
preferred velocity, a QP round (near / left / right), the sampled grid, the least-bad fallback.

    python benchmarks/swap_rounds.py [--n 1000] [--every 10] [--max-steps K] [--fast]
                                     [--out benchmarks/results_swap_rounds.md]
"""
from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_swarm import scenario  # noqa: E402


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
        # every vehicle of the swap has the same top speed: one configuration for all
        cfg = sel.options_for(inputs.limits.v_max, inputs.dt, inputs.sensing_range).config
        sw = inputs.arrays()
        out = np.empty((sw.who.shape[0], MANY_OUT_SIZE))
        decide_range(sw, 0, 1, cfg, out)  # once before timing
        for d in range(sw.who.shape[0]):
            t0 = time.perf_counter_ns()
            decide_range(sw, d, d + 1, cfg, out)
            elapsed = time.perf_counter_ns() - t0
            st = out_stats[ROUND_NAMES[int(out[d, 5])]]
            st["n"] += 1
            st["ns"] += elapsed
            st["solved"] += int(out[d, 6])
    return out_stats


def table(stats: dict[str, dict[str, float]]) -> list[str]:
    total_n = sum(s["n"] for s in stats.values())
    total_ns = sum(s["ns"] for s in stats.values())
    lines = ["| round | decisions | share of decisions | mean µs | share of time "
             "| QPs solved per decision |", "|---|---:|---:|---:|---:|---:|"]
    for name in ("preferred", "near", "left", "right", "sampled", "least_bad"):
        s = stats.get(name)
        if not s:
            continue
        mean_us = s["ns"] / s["n"] / 1e3
        lines.append(f"| {name} | {s['n']} | {s['n'] / total_n:.1%} | {mean_us:.1f} | "
                     f"{s['ns'] / total_ns:.1%} | {s['solved'] / s['n']:.1f} |")
    lines.append(f"| all | {total_n} | 100% | {total_ns / total_n / 1e3:.1f} | 100% | "
                 f"{sum(s['solved'] for s in stats.values()) / total_n:.1f} |")
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--every", type=int, default=10, help="keep every K-th select_many call")
    ap.add_argument("--max-steps", type=int, default=None)
    ap.add_argument("--fast", action="store_true", help="fly it with the fast preset")
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("results_swap_rounds.md"))
    args = ap.parse_args(argv)
    if args.n < 2 or args.every < 1:
        ap.error("--n must be at least 2 and --every at least 1")
    sel, calls = record(args.n, args.every, args.max_steps, args.fast)
    stats = replay(sel, calls)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).parent).stdout.strip() or "unknown"
    flown = "whole run" if args.max_steps is None else f"first {args.max_steps} steps"
    machine = platform.processor() or platform.machine()
    options = ", preset fast" if args.fast else ""
    lines = [f"## Sphere swap{options}, N = {args.n}, {flown}, every {args.every}th select_many "
             "call (odd and even steps alike) replayed", "", f"{platform.platform()}; {machine}; commit {commit}; "
             f"{time.strftime('%Y-%m-%d')}; one vehicle per compiled call, one thread.", "",
             *table(stats)]
    text = "\n".join(lines) + "\n"
    print(text)
    with args.out.open("a") as fh:
        fh.write(text + "\n")


if __name__ == "__main__":
    main()
