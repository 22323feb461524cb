"""Time of ``import vo3d_opt`` and of each formulation's first select() in a fresh process
(docs/results/first-call.md; docs/design-compiled-core.md).

Each row is its own child process on the README's example (a neighbour head-on and a
cylinder on the way): the time to import vo3d_opt, to import the formulation's backend library
(none for plane_qp on exact2d and for sampled: the compiled core), to construct the selector,
and its first select(); then a second select() for comparison, and for the default a first
select_many (two vehicles and the cylinder). Nothing is compiled at run time: the numeric core
is built with the package.

    python benchmarks/first_call.py [--runs 3] [--out docs/results/first-call.md]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from pages import RESULTS, command_line, machine_line, write_page

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
                  "first_select_s": t4 - t3, "second_select_s": t5 - t4,
                  "first_select_many_s": many}))
"""


def run(form: str, solver: str | None, lib: str | None) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps([form, solver, lib])],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def median(runs: list[dict[str, float]], key: str) -> float | None:
    vals = sorted(r[key] for r in runs if r[key] is not None)
    return vals[len(vals) // 2] if vals else None


def page(rows: list[dict[str, Any]], runs: int, machine: str, command: str) -> str:
    """The whole page: one row per (formulation, solver), medians over ``runs`` processes."""
    lines = ["# The first call", "", machine, "",
             f"`{command}`: each row its own fresh process on the README's example (a neighbour "
             "head-on and a cylinder on the way), the median of "
             f"{runs} process{'es' if runs > 1 else ''}: the time to import vo3d_opt, to import "
             "the formulation's backend library (none for the compiled core: `plane_qp` on "
             "exact2d and `sampled`), to construct the selector, its first `select()`, a second "
             "one, and for the default a first `select_many` (two vehicles and the cylinder). "
             "Nothing is compiled at run time: the numeric core is built with the package.", "",
             "| formulation | solver | import vo3d_opt s | backend import s | constructor s "
             "| first select() s | second select() s | first select_many() s |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        many = "—" if r["first_select_many_s"] is None else f"{r['first_select_many_s']:.4f}"
        lines.append(f"| {r['formulation']} | {r['solver'] or 'default'} | {r['import_s']:.3f} | "
                     f"{r['backend_s']:.3f} | {r['construct_s']:.3f} | "
                     f"{r['first_select_s']:.4f} | {r['second_select_s']:.5f} | {many} |")
    default = next((r for r in rows if r["first_select_many_s"] is not None), None)
    if default is not None:
        lines += ["", f"The default (`{default['formulation']}` on the compiled core): the first "
                  f"`select()` {default['first_select_s']:.4f} s and the first `select_many()` "
                  f"{default['first_select_many_s']:.4f} s after an import of vo3d_opt of "
                  f"{default['import_s']:.3f} s."]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3,
                    help="fresh processes per row; the median is shown")
    ap.add_argument("--out", type=Path, default=RESULTS / "first-call.md")
    args = ap.parse_args()
    if args.runs < 1:
        ap.error("--runs must be at least 1")
    rows = []
    for form, solver, lib in ROWS:
        runs = [run(form, solver, lib) for _ in range(args.runs)]
        rows.append({"formulation": form, "solver": solver,
                     **{k: median(runs, k) for k in runs[0]}})
        print(f"{form} {solver or 'default'}: done", file=sys.stderr, flush=True)
    write_page(args.out, page(rows, args.runs, machine_line(), command_line()))
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
