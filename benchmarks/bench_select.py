"""Time per select() for every formulation x installed backend.

Encounters: the own UAV at (0, 0, 20) m flying +x at 4 m/s; one neighbour head-on 30 m ahead
(so the preferred velocity is never safe: every call has to avoid), the others at random within
the 55 m sensing range, and with obstacles six random cylinders/boxes, one 20 m ahead.
Prints median and p99 microseconds per call, and plane_qp's speed-up over sampled. Each call
is timed as a control loop makes it: the obstacles persist (their prisms cached by a first
call), the neighbours are new objects every period.

    python benchmarks/bench_select.py [--encounters 40] [--repeat 3] [--quick] [--solvers S ...]
                                      [--deviation | --solved | --breakdown | --backends]
                                      [--fast-path] [--out docs/results/select.md]

``--breakdown``: one default decision (plane_qp on exact2d) split into the compiled kernel alone
(``kernel.decide`` on the arrays ``select`` would build) and the Python around it (checking the
inputs, building the arrays, the ``Decision``), with ``select_arrays`` and ``sampled`` timed on
the same encounters.

``--backends``: plane_qp on each Python-path backend (osqp, clarabel, daqp): the decision's
median and mean, the QPs it hands the backend, the solver's own time per QP (inside the
library's calls: DAQP's ``solve``, OSQP's ``setup``/``update``/``solve`` or its compiled solver's
``update_data_vec``/``update_data_mat``/``solve``, Clarabel's set-up,
``update`` and ``solve``) and ours per QP: around the solver call (the problem standardised,
screened and converted, the answer checked: ``Backend.solve`` less the solver's time) and over
the whole decision ((decision - solver) / QPs); each per QP figure the median over the
decisions of that decision's ratio.

``--out PATH``: also write what is printed to PATH as a results page, with the machine, the
date and the commit at the top.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import platform
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

import vo3d_opt
from vo3d_opt import AgentState, Box, Cylinder, Limits, Neighbor, VelocitySelector
from vo3d_opt.formulations import kernel
from vo3d_opt.formulations.common import bounds_array, neighbor_rows
from vo3d_opt.geometry.pyramid import prism_rows
from vo3d_opt.solvers import available_qp_solvers, get_backend

#: The backends of the Python path, each meant to decide in at most 300 µs at 9
#: neighbours x 6 obstacles.
PYTHON_PATH_BACKENDS = ("osqp", "clarabel", "daqp")


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


def fresh(neighbors: list[Neighbor]) -> list[Neighbor]:
    """The same neighbours as new objects (nothing cached on them), as each control period
    brings."""
    return [Neighbor(position=nb.position, velocity=nb.velocity, r_pz=nb.r_pz, cooperative=nb.cooperative)
            for nb in neighbors]


def time_calls(selector: VelocitySelector, cases: list[dict], repeat: int) -> tuple[np.ndarray, dict]:
    """µs per select() as a control loop calls it: the obstacles persist (each case is decided
    once first, as a loop's first period caches their prisms), the neighbours are new objects
    at every call (built outside the time)."""
    for kw in cases:
        selector.select(**kw)  # warm up caches, solver objects, the obstacles' prisms
    times, statuses = [], {}
    for _ in range(repeat):
        for kw in cases:
            d = selector.select(**{**kw, "neighbors": fresh(kw["neighbors"])})
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


def array_calls(selector: VelocitySelector, cases: list[dict], repeat: int) -> np.ndarray:
    """µs per ``select_arrays`` call on the cases as numpy arrays (as a control loop holds them)."""
    arrays = []
    for kw in cases:
        nbrs = kw["neighbors"]
        arrays.append(dict(
            position=np.array(kw["own"].position), velocity=np.array(kw["own"].velocity),
            preferred_velocity=np.array(kw["preferred_velocity"], dtype=float),
            neighbors=np.array([[*nb.position, *nb.velocity, nb.r_pz] for nb in nbrs]).reshape(-1, 7),
            cooperative=np.array([nb.cooperative for nb in nbrs], dtype=bool),
            obstacles=prism_rows(kw["obstacles"]), limits=kw["limits"], dt=kw["dt"]))
    for a in arrays:
        selector.select_arrays(**a)
    return np.array([selector.select_arrays(**a).solve_time for _ in range(repeat) for a in arrays]) * 1e6


def breakdown(rng: np.random.Generator, grid: list[tuple[int, int]], args: argparse.Namespace) -> None:
    """Median µs of the default decision, the kernel alone and the Python around it,
    select_arrays, and sampled."""
    print("Each select() is given its neighbours as new objects (a control loop's are new every "
          "period) and obstacles that persist; select_arrays() the same numbers as arrays.\n")
    print("| neighbours | obstacles | select() median µs | p99 µs | kernel alone median µs | "
          "Python around µs | select_arrays() median µs | sampled median µs | speed-up over sampled |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    default, ref = VelocitySelector(), VelocitySelector("sampled")
    for n, m in grid:
        cases = [encounter(rng, n, m, conflict=not args.fast_path) for _ in range(args.encounters)]
        t_sel, _ = time_calls(default, cases, args.repeat)
        t_ker = kernel_times(default, cases, args.repeat)
        t_arr = array_calls(default, cases, args.repeat) if hasattr(default, "select_arrays") else np.nan
        t_ref, _ = time_calls(ref, cases, 1)
        sel, ker, smp = np.median(t_sel), np.median(t_ker), np.median(t_ref)
        print(f"| {n} | {m} | {sel:.1f} | {np.percentile(t_sel, 99):.0f} | {ker:.1f} | {sel - ker:.1f} | "
              f"{np.median(t_arr):.1f} | {smp:.0f} | {smp / sel:.0f}x |", flush=True)


class SolverClock:
    """Seconds spent inside the solver libraries' own calls (DAQP's ``solve``; OSQP's
    ``setup``, ``update``, ``solve`` or its compiled solver's ``update_data_vec``,
    ``update_data_mat``, ``solve``; Clarabel's set-up, ``update``, ``solve``), by wrapping the
    names the backend modules call them by."""

    def __init__(self) -> None:
        self.seconds = 0.0

    def timed(self, fn):
        def call(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.seconds += time.perf_counter() - t0
        return call

    def wrapped(self, obj, methods: tuple[str, ...], inner: dict | None = None):
        """``obj`` with ``methods`` timed, and the objects named in ``inner`` wrapped in turn
        (OSQP's compiled solver, ``OSQP._solver``, which the backend calls directly)."""
        clock = self

        class Timed:
            def __getattr__(self, name):  # once per name: kept, later lookups are plain
                attr = getattr(obj, name)
                if name in (inner or {}):
                    attr = clock.wrapped(attr, inner[name])
                attr = clock.timed(attr) if name in methods else attr
                setattr(self, name, attr)
                return attr
        return Timed()

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        from vo3d_opt.solvers import clarabel_backend, daqp_backend, osqp_backend

        saved = (daqp_backend.daqp, osqp_backend.osqp, clarabel_backend.clarabel)
        daqp_backend.daqp = self.wrapped(saved[0], ("solve",))
        osqp_mod, clarabel_mod = saved[1], saved[2]

        def new_osqp():
            return self.wrapped(osqp_mod.OSQP(), ("setup", "update", "solve"),
                                {"_solver": ("update_data_vec", "update_data_mat", "solve")})

        osqp_proxy = self.wrapped(osqp_mod, ())
        osqp_proxy.__class__.OSQP = staticmethod(new_osqp)
        osqp_backend.osqp = osqp_proxy

        def new_clarabel(*a, **k):
            return self.wrapped(self.timed(clarabel_mod.DefaultSolver)(*a, **k), ("update", "solve"))

        clarabel_proxy = self.wrapped(clarabel_mod, ())
        clarabel_proxy.__class__.DefaultSolver = staticmethod(new_clarabel)
        clarabel_backend.clarabel = clarabel_proxy
        try:
            yield
        finally:
            daqp_backend.daqp, osqp_backend.osqp, clarabel_backend.clarabel = saved


def backend_figures(solver: str, cases: list[dict], repeat: int) -> dict[str, float]:
    """plane_qp on ``solver`` over ``cases``: decision µs (median, mean), QPs per decision, and
    per QP the solver's own µs, ours around the call and ours over the whole decision."""
    selector = VelocitySelector("plane_qp", solver)
    backend = get_backend(solver)
    clock, around = SolverClock(), SolverClock()
    real_solve = backend.solve
    backend.solve = around.timed(real_solve)  # the instance's, for this run only
    times, qps, inside, outside = [], [], [], []
    try:
        with clock.installed():
            getattr(backend, "_solvers", {}).clear()  # persistent solvers made under the clock
            for kw in cases[:3]:
                selector.select(**kw)  # set-up of the persistent solvers, caches
            for _ in range(repeat):
                for kw in cases:
                    s0, a0 = clock.seconds, around.seconds
                    d = selector.select(**kw)
                    times.append(d.solve_time)
                    qps.append(int(d.info.get("solved", 0)))
                    inside.append(clock.seconds - s0)
                    outside.append(around.seconds - a0)
    finally:
        del backend.solve
    t, s, a = (np.array(x) * 1e6 for x in (times, inside, outside))
    k = np.array(qps)
    some = k > 0  # per QP: the median over the decisions that solved any (a sum would take in
    # every time the process was preempted on a busy machine)
    return dict(median=float(np.median(t)), mean=float(t.mean()), p90=float(np.percentile(t, 90)),
                qps=float(k.mean()), solver=float(np.median(s[some] / k[some])),
                around=float(np.median((a[some] - s[some]) / k[some])),
                whole=float(np.median((t[some] - s[some]) / k[some])))


def backends(rng: np.random.Generator, grid: list[tuple[int, int]], args: argparse.Namespace) -> None:
    """The Python-path backends through plane_qp: time per decision, and ours per QP against
    the solver's."""
    solvers = [s for s in (args.solvers or PYTHON_PATH_BACKENDS) if s in available_qp_solvers()]
    print("| neighbours | obstacles | solver | median µs | mean µs | p90 µs | QPs per decision | "
          "solver µs per QP | ours around the call µs per QP | ours over the decision µs per QP |")
    print("|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for n, m in grid:
        cases = [encounter(rng, n, m, conflict=not args.fast_path) for _ in range(args.encounters)]
        for solver in solvers:
            f = backend_figures(solver, cases, args.repeat)
            print(f"| {n} | {m} | {solver} | {f['median']:.0f} | {f['mean']:.0f} | {f['p90']:.0f} | "
                  f"{f['qps']:.2f} | {f['solver']:.1f} | {f['around']:.1f} | {f['whole']:.1f} |", flush=True)


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
    ap.add_argument("--backends", action="store_true",
                    help="plane_qp on osqp, clarabel, daqp: our time per QP against the solver's")
    ap.add_argument("--out", type=Path, help="also write the output to this results page")
    args = ap.parse_args()
    with page(args.out):
        run(args)


def machine() -> str:
    """The machine, the date and the commit, for a results page's first lines."""
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor() or platform.machine()) \
        if Path("/proc/cpuinfo").exists() else platform.processor() or platform.machine()
    where = Path(vo3d_opt.__file__).parent  # the package measured: its checkout's commit
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=where).stdout.strip() or "unknown"
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                            ":!docs/results"],  # the pages being written are not the code measured
                           capture_output=True, text=True, cwd=where.parent).stdout.strip()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "unknown"
    return (f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
            f"CPython {platform.python_version()}, numpy {np.__version__}; "
            f"{time.strftime('%Y-%m-%d %H:%M')}; commit {commit}{' (with changes)' if dirty else ''}; "
            f"load average {load} at the start")


@contextlib.contextmanager
def page(out: Path | None) -> Iterator[None]:
    """Print as usual; with ``out``, also write everything printed to that page, headed by the
    command and the machine."""
    if out is None:
        yield
        return
    lines: list[str] = []
    real = sys.stdout

    class Tee:
        def write(self, text: str) -> int:
            lines.append(text)
            return real.write(text)

        def flush(self) -> None:
            real.flush()

    sys.stdout = Tee()
    try:
        yield
    finally:
        sys.stdout = real
    out.parent.mkdir(parents=True, exist_ok=True)
    head = (f"# `python benchmarks/bench_select.py {' '.join(sys.argv[1:])}`\n\n{machine()}\n\n")
    out.write_text(head + "".join(lines))


def run(args: argparse.Namespace) -> None:
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(7)
    grid = [(9, 6)] if args.quick else [(1, 0), (1, 6), (5, 0), (5, 6), (9, 6), (10, 0), (10, 6), (20, 0), (20, 6)]
    solvers = args.solvers or available_qp_solvers()
    combos = [("sampled", None)] + [("plane_qp", s) for s in solvers] \
        + [("cone_qp", s) for s in solvers if s != "exact2d"] + [("nlp", "casadi")]  # exact2d: plane_qp only
    print(f"# {platform.processor() or platform.machine()}, {platform.python_implementation()} "
          f"{platform.python_version()}, {time.strftime('%Y-%m-%d')}")
    if args.breakdown or args.backends:  # either or both
        if args.breakdown:
            breakdown(rng, grid, args)
        if args.backends:
            print()
            backends(rng, grid, args)
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
    print("Each call is given its neighbours as new objects (a control loop's are new every period) "
          "and obstacles that persist.\n")
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
