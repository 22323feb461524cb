"""Time of ``import vo3d_opt`` and of each formulation's first select() in a fresh process
(docs/results/compiled-core.md; docs/design-compiled-core.md).

Each row is its own child process on the README's example (a neighbour head-on and a
cylinder on the way): the time to import vo3d_opt, to import the formulation's backend library
(none for plane_qp on exact2d and for sampled: the compiled core), to construct the selector,
and its first select(); then a second select() for comparison, and for the default a first
select_many (two vehicles and the cylinder). Nothing is compiled at run time: the numeric core
is built with the package.

    python benchmarks/first_call.py [--runs 3]
"""
from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time

#: (formulation, solver, the backend's Python library, imported before the clock of select()).
ROWS = (
    ("plane_qp", None, None),
    ("sampled", None, None),
    ("plane_qp", "daqp", "daqp"),
    ("plane_qp", "osqp", "osqp"),
    ("cone_qp", None, "daqp"),
    ("cone_qp", "clarabel", "clarabel"),
    ("cone_qp", "cvxpy:CLARABEL", "cvxpy"),
    ("nlp", None, "casadi"),
)

CHILD = """
import importlib, json, sys, time
form, solver, lib = json.loads(sys.argv[1])
t0 = time.perf_counter()
import vo3d_opt
from vo3d_opt import AgentState, Cylinder, Limits, Neighbor, VelocitySelector
t1 = time.perf_counter()
if lib:
    importlib.import_module(lib)
t2 = time.perf_counter()
sel = VelocitySelector(form, solver)
t3 = time.perf_counter()
kw = dict(own=AgentState(position=(0, 0, 20), velocity=(4, 0, 0)), preferred_velocity=(4, 0, 0),
          neighbors=[Neighbor(position=(30, 0, 20), velocity=(-4, 0, 0), r_pz=10)],
          obstacles=[Cylinder(center=(15, 1), radius=2, height=30)], limits=Limits(), dt=0.2)
sel.select(**kw)
t4 = time.perf_counter()
sel.select(**kw)
t5 = time.perf_counter()
many = None
if form == "plane_qp" and solver is None:
    sel.select_many([(0, 0, 20), (30, 0, 20)], [(4, 0, 0), (-4, 0, 0)], [(4, 0, 0), (-4, 0, 0)],
                    10.0, obstacles=kw["obstacles"])
    many = time.perf_counter() - t5
print(json.dumps({"import_s": t1 - t0, "backend_s": t2 - t1, "construct_s": t3 - t2,
                  "first_select_s": t4 - t3, "second_select_s": t5 - t4, "first_select_many_s": many}))
"""


def run(form: str, solver: str | None, lib: str | None) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps([form, solver, lib])],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="fresh processes per row; the median is shown")
    args = ap.parse_args()
    print(f"# {platform.processor() or platform.machine()}, {platform.python_implementation()} "
          f"{platform.python_version()}, {time.strftime('%Y-%m-%d %H:%M')}; median of {args.runs} processes")
    print("| formulation | solver | import vo3d_opt s | backend import s | constructor s | first select() s "
          "| second select() s | first select_many() s |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for form, solver, lib in ROWS:
        runs = [run(form, solver, lib) for _ in range(args.runs)]

        def med(key: str) -> float | None:
            vals = sorted(r[key] for r in runs if r[key] is not None)
            return vals[len(vals) // 2] if vals else None

        many = med("first_select_many_s")
        print(f"| {form} | {solver or 'default'} | {med('import_s'):.3f} | {med('backend_s'):.3f} | "
              f"{med('construct_s'):.3f} | {med('first_select_s'):.4f} | {med('second_select_s'):.5f} | "
              f"{'—' if many is None else f'{many:.4f}'} |", flush=True)


if __name__ == "__main__":
    main()
