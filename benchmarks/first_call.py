"""Time of the first select() in a fresh process (README, Speed): with the ahead-of-time
kernel of ``vo3d compile``, and with numba's JIT, which compiles the kernels on a new checkout
and loads them from its on-disk cache afterwards.

Runs child processes on the contract's example: with numba's JIT kernel (``VO3D_AOT=0``) and
an empty numba cache directory (a new checkout), then again with that cache (now filled); and,
when ``vo3d compile`` has built the ahead-of-time kernel for this code, the same with it. Each
then times its first ``select_many`` (two vehicles and the cylinder), which compiles the rest
of the swarm kernel on top on the JIT (nothing with the ahead-of-time module, which holds the
k-d tree's neighbour lists too).

    python benchmarks/first_call.py [--build]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = """
import json, time
t0 = time.perf_counter()
from vo3d_opt import AgentState, Cylinder, Limits, Neighbor, VelocitySelector
t1 = time.perf_counter()
kw = dict(own=AgentState(position=(0, 0, 20), velocity=(4, 0, 0)), preferred_velocity=(4, 0, 0),
          neighbors=[Neighbor(position=(30, 0, 20), velocity=(-4, 0, 0), r_pz=10)],
          obstacles=[Cylinder(center=(15, 1), radius=2, height=30)], limits=Limits(), dt=0.2)
VelocitySelector().select(**kw)
t2 = time.perf_counter()
VelocitySelector().select_many([(0, 0, 20), (30, 0, 20)], [(4, 0, 0), (-4, 0, 0)], [(4, 0, 0), (-4, 0, 0)],
                               10.0, obstacles=kw["obstacles"])
t3 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "first_select_s": t2 - t1, "then_select_many_s": t3 - t2}))
"""


def run(env: dict[str, str]) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", action="store_true",
                    help="also time `vo3d compile` (building the ahead-of-time kernel) in a "
                         "scratch directory")
    args = ap.parse_args()
    from vo3d_opt.formulations import aot

    print(f"# {platform.processor() or platform.machine()}, {platform.python_implementation()} "
          f"{platform.python_version()}, {time.strftime('%Y-%m-%d')}")
    compiled, note = aot.load()
    print(f"# {note}")
    if args.build:
        with tempfile.TemporaryDirectory() as scratch:
            _, seconds = aot.build(Path(scratch))
        print(f"# building the ahead-of-time kernel (vo3d compile): {seconds:.1f} s")
    print("| kernel | numba cache | import s | first select() s | then first select_many() s |")
    print("|---|---|---:|---:|---:|")
    jit = {**os.environ, "VO3D_AOT": "0"}
    rows = []
    with tempfile.TemporaryDirectory() as cache_jit, tempfile.TemporaryDirectory() as cache_aot:
        # each kernel: a new numba cache directory, then the same one again (now warm)
        for when in ("empty (new checkout)", "warm (the run before it filled it)"):
            if compiled is not None:
                rows.append(("ahead of time", when,
                             run({**os.environ, "NUMBA_CACHE_DIR": cache_aot})))
            rows.append(("JIT (VO3D_AOT=0)", when, run({**jit, "NUMBA_CACHE_DIR": cache_jit})))
    for kernel, cache, r in rows:
        print(f"| {kernel} | {cache} | {r['import_s']:.2f} | {r['first_select_s']:.3f} | "
              f"{r['then_select_many_s']:.2f} |")


if __name__ == "__main__":
    main()
