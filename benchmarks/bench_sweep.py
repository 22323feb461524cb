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
  vo3d, e.g. ``pair:rvo2=2000``); ``--old-rows DIR`` reuses the old code's rows and wall
  times saved by an earlier run (``--save-old DIR``), which takes the old code long to fly.

    python benchmarks/bench_sweep.py [--family pair] [--n 2000] [--old-n 300]
        [--workers 1 2] [--rows pair=2000 group=2000 ...] [--old-rev REV]
        [--save-old DIR | --old-rows DIR] [--results docs/results/sweep-throughput.md]

Writes the whole page (``pages.py``: the machine line at the top) to ``--results``.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pandas as pd
from pages import RESULTS, command_line, machine_line, write_page

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


def throughput(args: argparse.Namespace, tree: Path, tmp: Path) -> dict[str, Any]:
    """Encounters per second of ``--family`` before and now on each worker count, and how the
    rows of the encounters both flew compare."""
    runs: list[dict[str, Any]] = []
    rows: dict[str, Path] = {}
    for label, where, n in (("before", tree, args.old_n), ("now", None, args.n)):
        for k in args.workers:
            path = tmp / f"tp-{label}-{k}.parquet"
            s = fly(where, args.family, n, k, path)
            rows.setdefault(label, path)
            runs.append({"code": label, "workers": k, "encounters": n, "setup_s": s["setup_time"],
                         "wall_s": s["wall_time"], "rate": s["encounters_per_second"]})
            print(runs[-1], file=sys.stderr, flush=True)
    n, c, bad = compare(pd.read_parquet(rows["before"]), pd.read_parquet(rows["now"]))
    return {"family": args.family, "runs": runs, "compared": n, "columns": c, "differ": bad}


def rows_check(args: argparse.Namespace, tree: Path, tmp: Path) -> list[dict[str, Any]]:
    """Each ``--rows`` family's encounters flown by both codes (or the old rows saved by an
    earlier run), compared column by column."""
    out = []
    for item in args.rows:
        name, _, count = item.partition("=")
        family, _, method = name.partition(":")
        method, n = method or "vo3d", int(count)
        saved = (args.old_rows / f"{family}-{method}.parquet") if args.old_rows else None
        if saved is not None and saved.exists():
            old = pd.read_parquet(saved)
            meta = saved.with_suffix(".json")
            wall_old = json.loads(meta.read_text())["wall_time"] if meta.exists() else None
            reused = True
        else:
            path = tmp / f"rows-before-{family}-{method}.parquet"
            s = fly(tree, family, n, 2, path, method)
            old, wall_old, reused = pd.read_parquet(path), s["wall_time"], False
            if args.save_old:
                args.save_old.mkdir(parents=True, exist_ok=True)
                shutil.copy(path, args.save_old / f"{family}-{method}.parquet")
                (args.save_old / f"{family}-{method}.json").write_text(
                    json.dumps({"wall_time": s["wall_time"]}))
        path = tmp / f"rows-now-{family}-{method}.parquet"
        s = fly(None, family, min(n, len(old)), 2, path, method)
        got, cols, bad = compare(old, pd.read_parquet(path))
        out.append({"family": family, "method": method, "encounters": got, "columns": cols,
                    "differ": bad, "wall_before": wall_old, "before_saved": reused,
                    "wall_now": s["wall_time"]})
        print(out[-1], file=sys.stderr, flush=True)
    return out


def throughput_section(tp: dict[str, Any]) -> list[str]:
    lines = [f"## Throughput: `{tp['family']}`, seed 0, the default method (vo3d, preset safe)",
             "", "| code | workers | encounters | setup s | wall s | encounters/s | per worker/s |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in tp["runs"]:
        lines.append(f"| {r['code']} | {r['workers']} | {r['encounters']} | {r['setup_s']:.1f} "
                     f"| {r['wall_s']:.2f} | {r['rate']:.3g} | {r['rate'] / r['workers']:.3g} |")
    same = "none differs" if not tp["differ"] else "DIFFER: " + ", ".join(tp["differ"])
    lines += ["", f"Rows of the {tp['compared']} encounters both flew: {tp['columns']} columns "
              f"compared (all but the timing columns), {same}.", ""]
    rate = {(r["code"], r["workers"]): r["rate"] for r in tp["runs"]}
    if ("now", 1) in rate and ("before", 1) in rate:
        lines.append(f"Per core (the one-worker rows): {rate[('now', 1)]:.3g} encounters/s now "
                     f"against {rate[('before', 1)]:.3g} before, "
                     f"{rate[('now', 1)] / rate[('before', 1)]:.3g} times.")
    more = [f"{rate[(code, 2)] / rate[(code, 1)]:.2f} times {code}"
            for code in ("before", "now") if (code, 1) in rate and (code, 2) in rate]
    if more:
        lines.append("Two workers against one: " + " and ".join(more) + " (below 2 when the "
                     "machine's second core is busy with other work: see the load in the machine "
                     "line).")
    return [*lines, ""]


def rows_section(checks: list[dict[str, Any]]) -> list[str]:
    lines = ["## Rows before and now, family by family (2 workers, seed 0)", "",
             "| family | method | encounters | columns compared | differing columns "
             "| wall s before | wall s now |", "|---|---|---:|---:|---|---:|---:|"]
    for r in checks:
        before = "–" if r["wall_before"] is None else f"{r['wall_before']:.0f}"
        before += " (saved)" if r["before_saved"] else ""
        lines.append(f"| {r['family']} | {r['method']} | {r['encounters']} | {r['columns']} | "
                     f"{', '.join(r['differ']) or 'none'} | {before} | {r['wall_now']:.0f} |")
    if any(r["before_saved"] for r in checks):
        lines += ["", "\"(saved)\": the old code's rows were flown by an earlier run of this "
                  "script (`--save-old`) and reused (`--old-rows`); its wall time is that run's, "
                  "under that run's load, so the two wall columns are not comparable."]
    return [*lines, ""]


def page(machine: str, command: str, tp: dict[str, Any] | None,
         checks: list[dict[str, Any]]) -> str:
    """The whole page from ``throughput``'s and ``rows_check``'s records."""
    lines = ["# Sweep throughput and rows: this code against the code before", "", machine, "",
             f"`{command}`: each measurement a fresh process running `run_sweep` on a fresh local "
             "Dask cluster (one thread per worker process), the clock from the first submission "
             "to the last row, after every worker has flown its warm-up encounter. The code "
             "before is the revision named in the machine line, checked out from git and its "
             "decision kernel compiled ahead of time. Rows are compared column by column, all but "
             "the timing columns (`TIMING_COLUMNS`).", ""]
    if tp is not None:
        lines += throughput_section(tp)
    if checks:
        lines += rows_section(checks)
    return "\n".join(lines)


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
    p.add_argument("--results", type=Path, default=RESULTS / "sweep-throughput.md")
    args = p.parse_args(argv)

    work = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
    try:
        tree = old_tree(args.old_rev, work)
        tp = None if args.no_throughput else throughput(args, tree, work)
        checks = rows_check(args, tree, work) if args.rows else []
        text = page(machine_line(against=args.old_rev), command_line(), tp, checks)
        write_page(args.results, text)
        print(text)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
