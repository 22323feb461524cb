"""Sweep throughput: encounters per second of ``vo3d sweep`` with 1 and 2 (or more) workers.

For each worker count, a fresh local Dask cluster (one thread per worker process) flies the
same N encounters of a family; the clock runs from the first submission to the last row, after
the cluster has started and every worker has flown its warm-up encounter (``setup`` column).
The rows of every run are checked to agree with the first (all columns but timing).

    python benchmarks/bench_sweep.py [--family pair] [--n 40] [--seed 0] [--workers 1 2]
                                     [--method vo3d|rvo2]

Prints a markdown table and the machine it ran on (CPU count and load average: on a shared
machine the figures are indicative only).
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys

from vo3d_opt.sweep import Method, run_sweep
from vo3d_opt.sweep.runner import rows_equal


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--family", default="pair", help="encounter family (default pair)")
    p.add_argument("--n", type=int, default=40, help="encounters per run (default 40)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts")
    p.add_argument("--method", choices=("vo3d", "rvo2"), default="vo3d")
    args = p.parse_args(argv)

    method = Method(name=args.method)
    rows, first = [], None
    for k in args.workers:
        result = run_sweep(args.family, args.n, seed=args.seed, workers=k, method=method,
                           progress=False)
        s = result.summary
        same = "-" if first is None else ("yes" if rows_equal(first.rows, result.rows) else "NO")
        first = first or result
        busy = float(result.rows["run_time"].sum())
        decisions = s["decisions"] or 0
        rows.append((k, s["encounters"], s["setup_time"], s["wall_time"], s["encounters_per_second"],
                     busy / s["encounters"], 1e6 * busy / decisions if decisions else float("nan"),
                     len(s["errors"]), same))
        print(f"{k} worker(s): {s['encounters_per_second']:.3g} encounters/s", file=sys.stderr)

    load = os.getloadavg() if hasattr(os, "getloadavg") else ("?",) * 3
    print(f"{datetime.date.today()}, {platform.machine()} {platform.system()}, "
          f"{os.cpu_count()} CPUs, load average {', '.join(f'{x:.2f}' for x in load)}; "
          f"family {args.family}, method {args.method}, N = {args.n}, seed {args.seed}\n")
    print("| workers | encounters | setup s | wall s | encounters/s | s per encounter (busy) "
          "| µs per decision (busy) | errors | same rows as first |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|:---:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.1f} | {r[3]:.2f} | {r[4]:.3g} | {r[5]:.3f} | "
              f"{r[6]:.0f} | {r[7]} | {r[8]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
