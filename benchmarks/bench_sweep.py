"""Sweep throughput, this code against an earlier commit, in one run; and the rows of both.

Each measurement is a fresh process that runs ``run_sweep`` on a fresh local Dask cluster (one
thread per worker process): the clock runs from the first submission to the last row, after
the cluster has started and every worker has flown its warm-up encounter. The earlier code
(``--old-rev``, default: the commit before the sweep's lockstep flights) is checked out from
git into a temporary directory and its decision kernel compiled ahead of time there (as
``make install`` does), so both fly with the same compiled kernel.

* throughput: ``--family`` (default pair), ``--n`` encounters with the new code and
  ``--old-n`` with the old one, on 1 and 2 workers; encounters per second, and per second
  per worker;
* rows (``--rows FAMILY=N ...``): the same N encounters of each family flown by both, compared
  column by column (all but the timing columns; ``FAMILY:METHOD=N`` for another method than
  vo3d, e.g. ``pair:rvo2=2000``); ``--old-rows DIR`` reuses the old code's rows
  saved by an earlier run (``--save-old DIR``), which takes the old code long to fly.

    python benchmarks/bench_sweep.py [--family pair] [--n 2000] [--old-n 300]
        [--workers 1 2] [--rows pair=2000 group=2000 ...] [--old-rev REV]
        [--save-old DIR | --old-rows DIR] [--results benchmarks/results_sweep_throughput.md]

Writes a markdown page (machine, date and commit at the top) to ``--results``.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd
from run_sweeps import cpu_model  # this folder's: the same machine line

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OLD_REV = "db9a6e5"

DRIVER = """
import json, sys
from vo3d_opt.sweep import Method, run_sweep

def main():
    family, n, workers, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    method = Method(name=sys.argv[5])
    r = run_sweep(family, n, seed=0, workers=workers, method=method, progress=False)
    r.rows.to_parquet(out, index=False)
    print(json.dumps(r.summary))

if __name__ == "__main__":
    main()
"""


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True,
                          text=True).stdout.strip()


def old_tree(rev: str, where: Path) -> Path:
    """The package at ``rev`` under ``where``, its kernel compiled ahead of time."""
    tree = where / f"vo3d-{rev}"
    if not (tree / "vo3d_opt").exists():
        tree.mkdir(parents=True)
        archive = subprocess.run(["git", "archive", rev], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
        print(f"compiling the kernel of {rev} ahead of time...", file=sys.stderr, flush=True)
        subprocess.run([sys.executable, "-m", "vo3d_opt.cli", "compile"], cwd=tree, check=True,
                       env={**os.environ, "PYTHONPATH": str(tree)}, stdout=subprocess.DEVNULL)
    return tree


def fly(
    tree: Path | None, family: str, n: int, workers: int, rows: Path, method: str = "vo3d"
) -> dict:
    """One sweep in a fresh process, with the package of ``tree`` (None: this checkout)."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    script = rows.with_suffix(".py")
    script.write_text(DRIVER)
    proc = subprocess.run([sys.executable, str(script), family, str(n), str(workers),
                           str(rows), method], env=env, capture_output=True, text=True,
                          check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def compare(old: pd.DataFrame, new: pd.DataFrame) -> tuple[int, int, list[str]]:
    """(rows compared, columns compared, columns that differ) over the common encounters."""
    from vo3d_opt.sweep.flight import TIMING_COLUMNS

    n = min(len(old), len(new))
    old, new = old.iloc[:n].reset_index(drop=True), new.iloc[:n].reset_index(drop=True)
    cols = [c for c in old.columns if c not in TIMING_COLUMNS]
    missing = sorted(set(cols) ^ {c for c in new.columns if c not in TIMING_COLUMNS})
    differ = [c for c in cols if c in new and not old[c].equals(new[c])]
    return n, len(cols), missing + differ


def header(args: argparse.Namespace) -> list[str]:
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return [
        "# Sweep throughput and rows: this code against the code before (`bench_sweep.py`)",
        "",
        f"{datetime.date.today()}, commit {git('rev-parse', '--short', 'HEAD')} against "
        f"{args.old_rev}; {cpu_model()}, {os.cpu_count()} CPUs, shared with other sessions "
        f"(load average {', '.join(f'{x:.2f}' for x in load)} at the end); "
        f"{platform.python_implementation()} {platform.python_version()}, "
        f"{platform.machine()} {platform.system()}.",
        "",
    ]


def throughput(args: argparse.Namespace, tree: Path, tmp: Path) -> tuple[list[str], dict]:
    lines = [
        f"## Throughput: `{args.family}`, seed 0, the default method (vo3d, preset safe)",
        "",
        "| code | workers | encounters | setup s | wall s | encounters/s | per worker/s |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    rows = {}
    for label, where, n in (("before", tree, args.old_n), ("now", None, args.n)):
        for k in args.workers:
            path = tmp / f"tp-{label}-{k}.parquet"
            s = fly(where, args.family, n, k, path)
            rows.setdefault(label, path)
            rate = s["encounters_per_second"]
            lines.append(f"| {label} | {k} | {n} | {s['setup_time']:.1f} | {s['wall_time']:.2f} "
                         f"| {rate:.3g} | {rate / k:.3g} |")
            print(lines[-1], file=sys.stderr, flush=True)
    n, c, bad = compare(pd.read_parquet(rows["before"]), pd.read_parquet(rows["now"]))
    lines += ["", f"Rows of the {n} encounters both flew: {c} columns compared (all but the "
              f"timing columns), {'none differs' if not bad else 'DIFFER: ' + ', '.join(bad)}.",
              ""]
    return lines, rows


def rows_check(args: argparse.Namespace, tree: Path, tmp: Path) -> list[str]:
    lines = [
        "## Rows before and now, family by family (2 workers, seed 0)",
        "",
        "| family | method | encounters | columns compared | differing columns | wall s before "
        "| wall s now |",
        "|---|---|---:|---:|---|---:|---:|",
    ]
    for item in args.rows:
        name, _, count = item.partition("=")
        family, _, method = name.partition(":")
        method, n = method or "vo3d", int(count)
        saved = (args.old_rows / f"{family}-{method}.parquet") if args.old_rows else None
        if saved is not None and saved.exists():
            old, wall_old = pd.read_parquet(saved), "(saved)"
        else:
            path = tmp / f"rows-before-{family}-{method}.parquet"
            s = fly(tree, family, n, 2, path, method)
            old, wall_old = pd.read_parquet(path), f"{s['wall_time']:.0f}"
            if args.save_old:
                args.save_old.mkdir(parents=True, exist_ok=True)
                shutil.copy(path, args.save_old / f"{family}-{method}.parquet")
        path = tmp / f"rows-now-{family}-{method}.parquet"
        s = fly(None, family, min(n, len(old)), 2, path, method)
        got, cols, bad = compare(old, pd.read_parquet(path))
        lines.append(f"| {family} | {method} | {got} | {cols} | {', '.join(bad) or 'none'} | "
                     f"{wall_old} | {s['wall_time']:.0f} |")
        print(lines[-1], file=sys.stderr, flush=True)
    return [*lines, ""]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--family", default="pair")
    p.add_argument("--n", type=int, default=2000, help="encounters, this code (default 2000)")
    p.add_argument("--old-n", type=int, default=300, help="encounters, the old code (300)")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--rows", nargs="*", default=[], metavar="FAMILY=N")
    p.add_argument("--old-rev", default=OLD_REV)
    p.add_argument("--save-old", type=Path)
    p.add_argument("--old-rows", type=Path)
    p.add_argument("--no-throughput", action="store_true")
    p.add_argument("--results", type=Path, default=HERE / "results_sweep_throughput.md")
    args = p.parse_args(argv)

    work = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
    try:
        tree = old_tree(args.old_rev, work)
        body: list[str] = []
        if not args.no_throughput:
            body += throughput(args, tree, work)[0]
        if args.rows:
            body += rows_check(args, tree, work)
        text = "\n".join(header(args) + body)
        args.results.write_text(text)
        print(text)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
