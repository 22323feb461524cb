"""Time per select() for every formulation x installed backend (issue: speed).

Encounters: the own UAV at (0, 0, 20) m flying +x at 4 m/s; one neighbour head-on 30 m ahead
(so the preferred velocity is never safe: every call has to avoid), the others at random within
the 55 m sensing range, and with obstacles six random cylinders/boxes, one 20 m ahead.
Prints median and p99 microseconds per call, and plane_qp's speed-up over sampled.

    python benchmarks/bench_select.py [--encounters 40] [--repeat 3] [--quick] [--solvers S ...]
                                      [--deviation | --solved | --breakdown] [--fast-path]

``--breakdown``: one default decision (plane_qp on exact2d) split into the compiled kernel alone
(``kernel.decide`` on the arrays ``select`` would build) and the Python around it (checking the
inputs, building the arrays, the ``Decision``), with ``sampled`` timed on the same encounters.
"""
from __future__ import annotations

import argparse
import platform
import time
import warnings

import numpy as np

from vo3d_opt import AgentState, Box, Cylinder, Limits, Neighbor, VelocitySelector
from vo3d_opt.formulations import kernel
from vo3d_opt.formulations.common import bounds_array, neighbor_rows
from vo3d_opt.geometry.pyramid import prism_rows
from vo3d_opt.solvers import available_qp_solvers


def encounter(rng: np.random.Generator, n: int, m: int, conflict: bool = True) -> dict:
    """Own UAV at (0, 0, 20) flying +x; with ``conflict`` a neighbour head-on 30 m ahead and a
    cylinder 20 m ahead, without it only neighbours and obstacles away from the path."""
    p = np.array([0.0, 0.0, 20.0])
    nbs = [Neighbor(position=(30.0, rng.uniform(-1, 1), 20.0 + rng.uniform(-1, 1)),
                    velocity=(-4.0, 0.0, 0.0), r_pz=10.0)] if conflict else []
    while len(nbs) < n:
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        pos = p + rng.uniform(12.0, 55.0) * d
        pos[2] = np.clip(pos[2], 1.0, 39.0)
        if np.linalg.norm(pos - p) > 11.0 and (conflict or pos[0] < -12.0):
            vel = rng.normal(size=3)
            nbs.append(Neighbor(position=pos, velocity=vel / np.linalg.norm(vel) * rng.uniform(0, 4), r_pz=10.0))
    obs = []
    if m and conflict:
        obs.append(Cylinder(center=(20.0, rng.uniform(-2, 2)), radius=2.0, height=30.0))
    while len(obs) < m:
        c = rng.uniform(-50, 50, 2)
        if np.linalg.norm(c) < 12 or not (conflict or c[0] < -12.0):
            continue
        if rng.random() < 0.5:
            obs.append(Cylinder(center=c, radius=rng.uniform(1, 4), height=rng.uniform(10, 45)))
        else:
            obs.append(Box(center=c, size=rng.uniform(2, 8, 2), height=rng.uniform(10, 45), yaw=rng.uniform(-3, 3)))
    return dict(own=AgentState(position=p, velocity=(4.0, 0.0, 0.0)), preferred_velocity=(4.0, 0.0, 0.0),
                neighbors=nbs, obstacles=obs, limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0)), dt=0.2)


def time_calls(selector: VelocitySelector, cases: list[dict], repeat: int) -> tuple[np.ndarray, dict]:
    for kw in cases[:3]:
        selector.select(**kw)  # warm up caches and solver objects
    times, statuses = [], {}
    for _ in range(repeat):
        for kw in cases:
            d = selector.select(**kw)
            times.append(d.solve_time)
            statuses[d.status] = statuses.get(d.status, 0) + 1
    return np.array(times) * 1e6, statuses


def kernel_times(selector: VelocitySelector, cases: list[dict], repeat: int) -> np.ndarray:
    """µs per call of the compiled decision ``select`` runs (``kernel.decide``, the compiled
    core) alone, on the arrays ``select`` builds for each case."""
    out, decide = np.empty(kernel.OUT_SIZE), kernel.decide
    args = [(kw["own"].position, kw["own"].velocity, np.asarray(kw["preferred_velocity"], dtype=float),
             neighbor_rows(kw["neighbors"]), prism_rows(kw["obstacles"]), bounds_array(kw["limits"], kw["dt"]),
             selector.options_for(kw["limits"].speed[1], kw["dt"]).config)
            for kw in cases]
    times = []
    for _ in range(repeat):
        for a in args:
            t0 = time.perf_counter()
            decide(*a, out)
            times.append(time.perf_counter() - t0)
    return np.array(times) * 1e6


def breakdown(rng: np.random.Generator, grid: list[tuple[int, int]], args: argparse.Namespace) -> None:
    """Median µs of the default decision, the kernel alone and the Python around it, and sampled."""
    print("| neighbours | obstacles | select() median µs | p99 µs | kernel alone median µs | "
          "Python around µs | sampled median µs | speed-up over sampled |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    default, ref = VelocitySelector(), VelocitySelector("sampled")
    for n, m in grid:
        cases = [encounter(rng, n, m, conflict=not args.fast_path) for _ in range(args.encounters)]
        t_sel, _ = time_calls(default, cases, args.repeat)
        t_ker = kernel_times(default, cases, args.repeat)
        t_ref, _ = time_calls(ref, cases, 1)
        sel, ker, smp = np.median(t_sel), np.median(t_ker), np.median(t_ref)
        print(f"| {n} | {m} | {sel:.1f} | {np.percentile(t_sel, 99):.0f} | {ker:.1f} | {sel - ker:.1f} | "
              f"{smp:.0f} | {smp / sel:.0f}x |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--encounters", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="only 9 neighbours x 6 obstacles")
    ap.add_argument("--deviation", action="store_true",
                    help="instead of times: mean |v - v_pref| per formulation (default backends)")
    ap.add_argument("--solvers", nargs="+", metavar="S",
                    help="only these QP backends (default: every installed one)")
    ap.add_argument("--solved", action="store_true",
                    help="instead of times: QPs solved per plane_qp decision, on each backend")
    ap.add_argument("--breakdown", action="store_true",
                    help="the default decision: select() vs the compiled kernel alone, and sampled")
    ap.add_argument("--fast-path", action="store_true",
                    help="encounters where the preferred velocity is already safe (all behind)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(7)
    grid = [(9, 6)] if args.quick else [(1, 0), (1, 6), (5, 0), (5, 6), (9, 6), (10, 0), (10, 6), (20, 0), (20, 6)]
    solvers = args.solvers or available_qp_solvers()
    combos = [("sampled", None)] + [("plane_qp", s) for s in solvers] \
        + [("cone_qp", s) for s in solvers if s != "exact2d"] + [("nlp", "casadi")]  # exact2d: plane_qp only
    print(f"# {platform.processor() or platform.machine()}, {platform.python_implementation()} "
          f"{platform.python_version()}, {time.strftime('%Y-%m-%d')}")
    if args.breakdown:
        breakdown(rng, grid, args)
        return
    if args.deviation:
        print("| neighbours | obstacles | formulation | mean deviation m/s | max deviation m/s |")
        print("|---:|---:|---|---:|---:|")
        for n, m in grid:
            cases = [encounter(rng, n, m, conflict=not args.fast_path) for _ in range(args.encounters)]
            for form in ("sampled", "plane_qp", "cone_qp", "nlp"):
                sel = VelocitySelector(form)
                dev = [np.linalg.norm(sel.select(**kw).velocity - np.asarray(kw["preferred_velocity"]))
                       for kw in cases]
                print(f"| {n} | {m} | {form} | {np.mean(dev):.2f} | {np.max(dev):.2f} |", flush=True)
        return
    if args.solved:
        print("| neighbours | obstacles | solver | mean QPs solved | median | max |")
        print("|---:|---:|---|---:|---:|---:|")
        for n, m in grid:
            cases = [encounter(rng, n, m, conflict=not args.fast_path) for _ in range(args.encounters)]
            for solver in solvers:
                sel = VelocitySelector("plane_qp", solver=solver)
                k = np.array([sel.select(**kw).info.get("solved", 0) for kw in cases])
                print(f"| {n} | {m} | {solver} | {k.mean():.2f} | {np.median(k):.0f} | {k.max()} |", flush=True)
        return
    print("| neighbours | obstacles | formulation | solver | median µs | p99 µs | statuses |")
    print("|---:|---:|---|---|---:|---:|---|")
    for n, m in grid:
        cases = [encounter(rng, n, m, conflict=not args.fast_path) for _ in range(args.encounters)]
        medians = {}
        for form, solver in combos:
            rep = 1 if form in ("sampled", "nlp") or solver.startswith("cvxpy") else args.repeat
            t, st = time_calls(VelocitySelector(form, solver=solver), cases, rep)
            medians[(form, solver)] = np.median(t)
            print(f"| {n} | {m} | {form} | {solver or '-'} | {np.median(t):.0f} | {np.percentile(t, 99):.0f} | "
                  + ", ".join(f"{k}: {v}" for k, v in sorted(st.items())) + " |", flush=True)
        qp = {k: v for k, v in medians.items() if k[0] == "plane_qp"}
        best = min(qp, key=qp.get)
        print(f"| {n} | {m} | **fastest plane_qp** | {best[1]} | {qp[best]:.0f} | | "
              f"{medians[('sampled', None)] / qp[best]:.0f}x faster than sampled |", flush=True)


if __name__ == "__main__":
    main()
