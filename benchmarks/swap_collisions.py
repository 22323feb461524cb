"""What the vehicles of the sphere swap did before they collided: the swap flown
with ours on every core (``select_many``, max_neighbors 10, the simulator's defaults), then, for
the first pairs that came within ``--within`` m of each other at a step, the steps before:
their distances, speeds and statuses, and whether each had the other among its neighbours.

    python benchmarks/swap_collisions.py [--n 10000] [--within 1.0] [--pairs 200]

An investigation, not a results page: it prints what it finds (under the machine line of
``pages.py``).
"""
from __future__ import annotations

import argparse
import collections
import json
import time

import numpy as np
from bench_swarm import scenario  # this folder's
from pages import machine_line
from scipy.spatial import cKDTree

from vo3d_opt import swarm
from vo3d_opt.sim.deciders import SwarmSelect
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.simulator import fly, scenario_selector
from vo3d_opt.swarm import cores

BEFORE = 4  # steps shown before a pair's first step within range


def first_within(positions: np.ndarray, within: float) -> dict[tuple[int, int], int]:
    """Each vehicle pair's first step closer than ``within`` (m)."""
    first: dict[tuple[int, int], int] = {}
    for k in range(positions.shape[0]):
        for i, j in cKDTree(positions[k]).query_pairs(within):
            first.setdefault((int(i), int(j)), k)
    return first


def sees(rec, k: int, i: int, j: int) -> int:
    """How many of i and j had the other among its neighbours at step k (0, 1 or 2)."""
    who = np.flatnonzero(rec.decided[k]).astype(np.int64)
    span, idx = swarm.vehicle_links(np.ascontiguousarray(rec.positions[k]), who, 55.0, 10)
    row = {int(w): r for r, w in enumerate(who)}
    listed = {a: set(idx[span[row[a], 0] : span[row[a], 1]]) if a in row else set() for a in (i, j)}
    return int(j in listed[i]) + int(i in listed[j])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--within", type=float, default=1.0)
    ap.add_argument("--pairs", type=int, default=200)
    args = ap.parse_args()
    sc = scenario("swap", args.n)
    sel, _, _ = scenario_selector(sc)
    step = SwarmSelect(sc, sel, max_neighbors=10, threads=cores())
    t0 = time.perf_counter()
    rec = fly(sc, step, progress=False)
    print(f"# sphere swap, N = {args.n}, flown in {time.perf_counter() - t0:.0f} s\n\n"
          f"{machine_line()}\n")
    s = summarize(rec)
    keys = ("min_vehicle_distance", "pz_intrusions", "collisions", "reached", "arrival_time_max",
            "fallbacks", "status_counts")
    print(json.dumps({k: s[k] for k in keys}), "\n")
    first = first_within(rec.positions, args.within)
    print(f"pairs within {args.within} m at some step: {len(first)}\n")
    shown = sorted(first.items(), key=lambda item: item[1])[: args.pairs]
    statuses: collections.Counter[str] = collections.Counter()
    names = np.array(rec.status_names, dtype=object)  # codes spelt out only where read
    seen = 0
    print("| pair | step within r_pz | step within range | distances (m) | speeds i, j (m/s) "
          "| statuses i, j |")
    print("|---|---:|---:|---|---|---|")
    for n_shown, ((i, j), k) in enumerate(shown):
        lo = max(0, k - BEFORE)
        d = np.linalg.norm(rec.positions[: k + 1, i] - rec.positions[: k + 1, j], axis=1)
        statuses.update(str(x) for x in names[rec.status_codes[lo:k, [i, j]]].ravel())
        seen += sees(rec, k - 1, i, j) if k >= 1 else 0
        if n_shown < 8:
            v = np.linalg.norm(rec.velocities[lo:k][:, [i, j]], axis=-1).round(2)
            st = [sorted(set(map(str, names[rec.status_codes[lo:k, a]]))) for a in (i, j)]
            inside = np.flatnonzero(d < float(sc.r_pz.max()))
            print(f"| {i}, {j} | {inside[0] if inside.size else '–'} | {k} | "
                  f"{d[lo : k + 1].round(2).tolist()} | {v.T.tolist()} | {st} |")
    print(f"\nstatuses of both vehicles over the {BEFORE} steps before, first {len(shown)} pairs: "
          f"{dict(statuses)}")
    print(f"each in the other's neighbour list at the step before: {seen} of {2 * len(shown)}")


if __name__ == "__main__":
    main()
