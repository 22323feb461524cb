"""The first minutes of a user (docs/results/first-minutes.md): the wheel installed with no extra
into a fresh venv, how many packages and megabytes that is and how long it takes, ``import
vo3d_opt``, and the first call of every formulation and backend, each in a fresh process; then
the same after ``pip install`` of the solver extras ([qp,cvxpy,nlp]) and of [sim] (with the
first ``vo3d run``). Nothing is compiled at run time: the numeric core is built with the wheel.

Each first-call row is benchmarks/first_call.py's child process (the README's first example: a
neighbour head-on and a cylinder): the time to import vo3d_opt, to import the backend's library
(none for exact2d and sampled), to construct the selector, its first select(), then a second
one to compare; and the README's 100-vehicle select_many() in a process of its own (first and
second call). The median of ``--runs`` processes is shown.

    python benchmarks/first_minutes.py [--runs 3] [--out docs/results/first-minutes.md]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from first_call import CHILD
from pages import machine_line, write_page  # this folder's: the one machine line

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "results" / "first-minutes.md"

#: The library each backend imports (its import time is the backend's own, not ours).
LIBRARIES = {"osqp": "osqp", "clarabel": "clarabel", "daqp": "daqp", "cvxpy": "cvxpy",
             "qpsolvers": "qpsolvers", "casadi": "casadi"}

#: The README's 100-vehicle select_many() with the default selector: its first call (after a
#: first select()) and its second, in a fresh process.
MANY = """
import json, time
import numpy as np
from vo3d_opt import AgentState, Cylinder, Limits, VelocitySelector
sel = VelocitySelector()
limits = Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0))
sel.select(own=AgentState(position=(0.0, 0.0, 20.0), velocity=(4.0, 0.0, 0.0)),
           preferred_velocity=(4.0, 0.0, 0.0), limits=limits, dt=0.2)
rng = np.random.default_rng(0)
many = dict(positions=rng.uniform((0.0, 0.0, 10.0), (500.0, 500.0, 30.0), size=(100, 3)),
            velocities=np.zeros((100, 3)), preferred_velocities=np.tile((4.0, 0.0, 0.0), (100, 1)),
            r_pz=8.0, obstacles=[Cylinder(center=(15.0, 8.0), radius=3.0, height=30.0)],
            limits=limits, dt=0.2, sensing_range=55.0, max_neighbors=10)
t0 = time.perf_counter()
sel.select_many(**many)
t1 = time.perf_counter()
sel.select_many(**many)
print(json.dumps({"first": t1 - t0, "second": time.perf_counter() - t1}))
"""

INVENTORY = """
import json
from importlib import metadata
rows = []
for dist in metadata.distributions():
    size = sum(f.stat().st_size for f in map(dist.locate_file, dist.files or []) if f.is_file())
    rows.append([dist.metadata["Name"], size])
print(json.dumps(sorted(rows)))
"""

SOLVERS = """
import json
from vo3d_opt.solvers import available_qp_solvers, available_solvers
print(json.dumps([available_solvers(), available_qp_solvers()]))
"""

MISSING = """
from vo3d_opt import VelocitySelector
try:
    VelocitySelector("nlp")
except ImportError as exc:
    print(exc)
"""


def run(cmd: list[str | Path], **kw: Any) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, env=env,
                          check=True, **kw)


def timed(cmd: list[str | Path], **kw: Any) -> float:
    t = time.perf_counter()
    run(cmd, **kw)
    return time.perf_counter() - t


def child_json(python: Path, code: str, *args: str, cwd: Path) -> Any:
    return json.loads(run([python, "-c", code, *args], cwd=cwd).stdout.strip().splitlines()[-1])


def inventory(python: Path, cwd: Path) -> dict[str, int]:
    return dict(child_json(python, INVENTORY, cwd=cwd))


def median_of(rows: list[dict[str, Any]]) -> dict[str, Any]:
    keys = [k for k in rows[0] if isinstance(rows[0][k], float)]
    return {**rows[0], **{k: statistics.median(r[k] for r in rows) for k in keys}}


def many_calls(python: Path, runs: int, cwd: Path) -> dict[str, float]:
    return median_of([child_json(python, MANY, cwd=cwd) for _ in range(runs)])


def first_calls(python: Path, pairs: list[tuple[str, str | None]], runs: int,
                cwd: Path) -> list[dict[str, Any]]:
    out = []
    for form, solver in pairs:
        lib = LIBRARIES.get((solver or "").partition(":")[0])
        if form == "cone_qp" and solver is None:
            lib = "daqp"
        if form == "nlp" and solver is None:
            lib = "casadi"
        arg = json.dumps([form, solver, lib])
        runs_of = [child_json(python, CHILD, arg, cwd=cwd) for _ in range(runs)]
        out.append({"formulation": form, "solver": solver or "default", **median_of(runs_of)})
    return out


def import_times(python: Path, runs: int, cwd: Path) -> dict[str, float]:
    code = "import time; t = time.perf_counter(); import vo3d_opt; print(time.perf_counter() - t)"
    inside = [float(run([python, "-c", code], cwd=cwd).stdout) for _ in range(runs)]
    bare = [timed([python, "-c", "pass"], cwd=cwd) for _ in range(runs)]
    whole = [timed([python, "-c", "import vo3d_opt"], cwd=cwd) for _ in range(runs)]
    return {"import": statistics.median(inside), "process": statistics.median(whole),
            "bare": statistics.median(bare)}


def all_pairs(python: Path, cwd: Path) -> list[tuple[str, str | None]]:
    solvers, qp = child_json(python, SOLVERS, cwd=cwd)
    pairs: list[tuple[str, str | None]] = [("plane_qp", None), ("sampled", None)]
    pairs += [("plane_qp", s) for s in qp if s != "exact2d"]
    if "daqp" in qp:
        pairs.append(("cone_qp", None))
    pairs += [("cone_qp", s) for s in qp if s not in ("exact2d", "daqp")]
    if any(s.startswith("casadi") for s in solvers):
        pairs.append(("nlp", None))
    pairs += [("nlp", s) for s in solvers if s.startswith("casadi:")]
    return pairs


def mb(n: float) -> str:
    return f"{n / 1e6:.1f}"


def call_table(rows: list[dict[str, Any]]) -> list[str]:
    lines = ["| formulation | solver | import vo3d_opt s | library import s | constructor s | "
             "first select() s | second select() ms |", "|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['formulation']} | {r['solver']} | {r['import_s']:.3f} | "
                     f"{r['backend_s']:.3f} | {r['construct_s']:.3f} | {r['first_select_s']:.3f} | "
                     f"{r['second_select_s'] * 1e3:.2f} |")
    return lines


def package_lines(title: str, before: dict[str, int], after: dict[str, int],
                  seconds: float) -> list[str]:
    added = {k: v for k, v in after.items() if k not in before}
    top = sorted(added.items(), key=lambda kv: -kv[1])[:6]
    return [f"- {title}: {len(added)} packages, {mb(sum(added.values()))} MB installed, "
            f"{seconds:.1f} s (`pip install` from the local package mirror); the largest: "
            + ", ".join(f"{k} {mb(v)} MB" for k, v in top)]


def measure(runs: int, work: Path) -> list[str]:
    t = time.perf_counter()
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
         work / "dist", ROOT])
    wheel_s = time.perf_counter() - t
    (wheel,) = (work / "dist").glob("vo3d_opt-*.whl")
    venv = work / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", venv])
    python = venv / "bin" / "python"
    pip = [sys.executable, "-m", "pip", "--python", python, "install", "-q"]
    core_s = timed([*pip, wheel])
    core = inventory(python, work)
    lines = [f"- the wheel (`pip wheel --no-deps --no-build-isolation .`, its build directory "
             f"kept): {wheel_s:.1f} s, {mb(wheel.stat().st_size)} MB",
             *package_lines("core install, `pip install vo3d_opt-*.whl` into a fresh venv "
                            "(vo3d-opt counted)", {}, core, core_s),
             "  (" + ", ".join(sorted(core)) + ")"]
    imp = import_times(python, max(runs, 5), work)
    lines.append(f"- `import vo3d_opt`: {imp['import']:.3f} s inside the process; the whole "
                 f"`python -c 'import vo3d_opt'` {imp['process']:.3f} s against "
                 f"{imp['bare']:.3f} s for `python -c pass` (medians of {max(runs, 5)})")
    missing = run([python, "-c", MISSING], cwd=work).stdout.strip()
    vo3d = subprocess.run([venv / "bin" / "vo3d", "--version"], capture_output=True, text=True)
    lines += ["- without the extras: `VelocitySelector(\"nlp\")` raises ImportError "
              f"`{missing}`; `vo3d --version` exits {vo3d.returncode} with "
              f"`{vo3d.stderr.strip()}`", ""]
    core_rows = first_calls(python, all_pairs(python, work), runs, work)
    many = many_calls(python, runs, work)
    lines += ["First calls after the core install (fresh processes):", "",
              *call_table(core_rows), "",
              f"The README's 100-vehicle `select_many()` (default selector, after its first "
              f"select()): first call {many['first']:.3f} s, second "
              f"{many['second'] * 1e3:.1f} ms.", ""]
    t = time.perf_counter()
    run([*pip, f"{wheel}[qp,cvxpy,nlp]"])
    solvers_s = time.perf_counter() - t
    with_solvers = inventory(python, work)
    rows = first_calls(python, all_pairs(python, work), runs, work)
    lines += [*package_lines("`[qp,cvxpy,nlp]` on top", core, with_solvers, solvers_s), "",
              "First calls of every formulation and backend after it (fresh processes):", "",
              *call_table(rows), ""]
    t = time.perf_counter()
    run([*pip, f"{wheel}[sim]"])
    sim_s = time.perf_counter() - t
    with_sim = inventory(python, work)
    cli_s = timed([venv / "bin" / "vo3d", "run", "paper-flight-test", "--json", "-q"], cwd=work)
    lines += [*package_lines("`[sim]` on top", with_solvers, with_sim, sim_s),
              f"- then the first `vo3d run paper-flight-test --json` (a whole run): {cli_s:.1f} s",
              ""]
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="fresh processes per row (median shown)")
    ap.add_argument("--out", type=Path, default=OUT, help="the results page (written whole)")
    args = ap.parse_args()
    head = ["# First minutes: install, import, first calls", "", machine_line(), "",
            "`python benchmarks/first_minutes.py`; other work on the machine slows every figure "
            "alike.", ""]
    with tempfile.TemporaryDirectory(prefix="first-minutes-") as tmp:
        body = measure(args.runs, Path(tmp))
    page = "\n".join(head + body) + "\n"
    print(page)
    write_page(args.out, page)


if __name__ == "__main__":
    main()
