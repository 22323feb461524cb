"""The evidence sweeps of issue 13: every family's rates, ours and RVO2-3D's, in one table.

Three stages (all by default, or those named with ``--stages``):

* ``throughput``: encounters per second of the same ``--bench-n`` encounters of
  ``--bench-family`` with 1 and 2 workers (``bench_sweep.py``), written to
  ``OUT_ROOT/throughput.md``;
* ``sweeps``: ``vo3d sweep FAMILY --n N --seed S --workers K --out OUT_ROOT/FAMILY --json`` for
  every family of ``--families``, and ``--method rvo2`` into ``OUT_ROOT/FAMILY-rvo2`` for every
  family of ``--rvo2`` (obstacle-free ones: the same encounters), each as its own process;
  with several ``--seeds``, seed 0 goes there and seed S into ``.../seedS``;
* ``table``: ``benchmarks/results_sweeps.md`` from the runs found under ``OUT_ROOT`` and
  ``throughput.md`` (so the table can be rebuilt without flying anything). The runs of one
  family and method with different seeds are independent encounters (the stream of encounter
  i is seeded by (seed, i)): their rows are pooled into one line, rates and bounds recomputed.

    python benchmarks/run_sweeps.py --n 10000 [--families pair group dense lagged]
        [--rvo2 pair dense] [--seeds 0] [--workers 2] [--out-root /work/sweep-out]
        [--stages throughput sweeps table] [--results benchmarks/results_sweeps.md]
        [--selector-option KEY=VALUE ...]

``--n`` is one N for every family, or ``FAMILY=N`` items for per-family counts.
``--selector-option`` passes ``-o KEY=VALUE`` to every ``vo3d`` sweep (not RVO2-3D's nor the
throughput stage's); the table names the options beside the method. Such runs need their own
``--out-root`` and ``--results`` (refused without them: they would overwrite the defaults').
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
FAMILIES = ("pair", "group", "dense", "lagged")
RVO2 = ("pair", "dense")
#: An intrusion "deeper than 1 %": closest approach below 0.99 of the pair's larger r_pz.
DEEP = 0.99


def counts(items: list[str], families: list[str]) -> dict[str, int]:
    """``["10000"]`` or ``["pair=10000", "group=5000", ...]`` as {family: N}."""
    if len(items) == 1 and "=" not in items[0]:
        return dict.fromkeys(families, int(items[0]))
    out = {}
    for item in items:
        name, _, n = item.partition("=")
        out[name] = int(n)
    missing = [f for f in families if f not in out]
    if missing:
        raise SystemExit(f"--n: no count for {', '.join(missing)}")
    return out


def vo3d_cmd() -> list[str]:
    script = Path(sys.executable).with_name("vo3d")
    return [str(script)] if script.exists() else [sys.executable, "-m", "vo3d_opt.cli"]


def run_dir(out_root: Path, family: str, method: str, seed: int) -> Path:
    base = out_root / (family if method == "vo3d" else f"{family}-{method}")
    return base if seed == 0 else base / f"seed{seed}"


def pooled(dirs: list[Path]) -> dict[str, Any]:
    """One summary for the runs in ``dirs`` (the same family and method, other seeds): the
    summary of their pooled rows, wall times summed."""
    import pandas as pd

    from vo3d_opt.sweep.stats import aggregate

    summaries = [json.loads((d / "summary.json").read_text()) for d in dirs]
    rows = pd.concat([pd.read_parquet(d / "encounters.parquet") for d in dirs],
                     ignore_index=True)
    first = summaries[0]
    s = first
    if len(summaries) > 1:
        s = aggregate(rows, family=first["family"], seed=first["seed"], method=first["method"],
                      formulation=first["formulation"], solver=first["solver"])
        wall = sum(x["wall_time"] for x in summaries)
        if any(x.get("selector_options") != first.get("selector_options") for x in summaries):
            raise SystemExit(f"{dirs}: the seeds ran with different selector options")
        s.update({"seed": [x["seed"] for x in summaries], "wall_time": wall,
                  "selector_options": first.get("selector_options", {}),
                  "encounters_per_second": s["encounters"] / wall, "workers": first["workers"]})
    s["deep_intrusions"] = int((rows["min_normalised_distance"] < DEEP).sum())
    return s


def run_one(family: str, n: int, *, seed: int, workers: int, method: str, out: Path,
            options: list[str]) -> None:
    """One ``vo3d sweep`` process; its stderr (progress) goes to ``out/sweep.log``."""
    out.mkdir(parents=True, exist_ok=True)
    cmd = vo3d_cmd() + ["sweep", family, "--n", str(n), "--seed", str(seed), "--workers",
                        str(workers), "--method", method, "--out", str(out), "--json"]
    if method == "vo3d":
        cmd += [arg for option in options for arg in ("-o", option)]
    print(" ".join(cmd), file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    with open(out / "sweep.log", "w") as log:
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=log, text=True)
    if proc.returncode not in (0, 1):  # 1: some encounters raised (listed in the summary)
        raise SystemExit(f"{family} ({method}): exit status {proc.returncode}, see {out}/sweep.log")
    summary = json.loads(proc.stdout)
    (out / "command.txt").write_text(" ".join(cmd) + "\n")
    print(f"  {family} ({method}): {summary['encounters']} encounters in "
          f"{time.perf_counter() - t0:.0f} s, collisions {summary['encounters_with_collision']}, "
          f"intrusions {summary['encounters_with_intrusion']}, errors {len(summary['errors'])}",
          file=sys.stderr, flush=True)


def throughput(family: str, n: int, seed: int, out_root: Path) -> None:
    """``bench_sweep.py`` (seed 0, this code against the one before) with 1 and 2 workers, its
    page to ``out_root/throughput.md`` (``seed`` is not used: the benchmark flies seed 0)."""
    out_root.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, str(HERE / "bench_sweep.py"), "--family", family, "--n", str(n),
           "--workers", "1", "2", "--results", str(out_root / "throughput.md")]
    print(" ".join(cmd), file=sys.stderr, flush=True)
    subprocess.run(cmd, stdout=subprocess.DEVNULL, check=True)


# ------------------------------------------------------------------------------ the table


def _rate(r: dict[str, Any]) -> str:
    lo, hi = r["ci95"]
    return f"{r['rate']:.2%} [{lo:.2%}, {hi:.2%}]"


def _pct(x: float) -> str:
    return f"{x:.3%}" if x < 0.01 else f"{x:.2%}"


def summary_row(s: dict[str, Any]) -> str:
    r = s["rates"]
    options = ", ".join(f"{k}: {json.dumps(v)}" for k, v in s.get("selector_options", {}).items())
    label = "plane_qp" + (f"; {options}" if options else "")
    name = f"ours ({label})" if s["method"] == "vo3d" else "RVO2-3D"
    return (f"| {s['family']} | {name} | {s['encounters']} | {len(s['errors'])} | "
            f"{s['encounters_with_collision']} ({s['collisions']}) | "
            f"{s['encounters_with_intrusion']} ({s['pz_intrusions']}) | {s['deep_intrusions']} | "
            f"{s['encounters_not_all_arrived']} ({s['not_arrived']}) | "
            f"{r['limit_violation']['events']} ({s['limit_violations']}) | "
            f"{_pct(s['collision_rate_upper95'])} | {_rate(r['intrusion'])} | "
            f"{s['min_normalised_distance']:.3f} | {s['wall_time']:.0f} | "
            f"{s['encounters_per_second']:.2f} |")


def commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, check=True,
                              capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def table(out_root: Path, families: list[str], rvo2: list[str]) -> str:
    runs = [out_root / f for f in families] + [out_root / f"{f}-rvo2" for f in rvo2]
    summaries = {}
    for path in runs:
        dirs = [d for d in [path, *sorted(path.glob("seed*"))] if (d / "summary.json").exists()]
        if dirs:
            summaries[path.name] = pooled(dirs)
        else:
            print(f"missing {path}/summary.json: left out of the table", file=sys.stderr)
    first = next(iter(summaries.values()), {})
    seeds = sorted({x for s in summaries.values()
                    for x in (s["seed"] if isinstance(s["seed"], list) else [s["seed"]])})
    lines = [
        "# Sweep results (`benchmarks/run_sweeps.py`)",
        "",
        f"{datetime.date.today()}, commit {commit()}; {cpu_model()}, {os.cpu_count()} CPUs "
        f"shared with other sessions (load average during the runs not controlled); "
        f"{platform.python_implementation()} {platform.python_version()}; seeds "
        f"{', '.join(map(str, seeds))} (encounters 0..N_seed-1 of each), "
        f"{first.get('workers', '?')} local Dask workers.",
        "",
        "Counts are encounters (and events in brackets: vehicle pairs for collisions and "
        "intrusions, agents for not arrived, samples for limit violations). Rates per encounter "
        "with Clopper–Pearson bounds: collision one-sided upper 95 %, intrusion two-sided 95 % "
        "CI. min d/r_pz: the smallest closest approach over the larger protected-zone radius "
        "of the pair, over all encounters; \"deeper than 1 %\": encounters where it fell below "
        "0.99 (vehicle pairs). RVO2-3D flies the same encounters (obstacle-free "
        "families only), every agent with radius max(r_pz)/2.",
        "",
        "| family | method | N | errors | collisions | intrusions | deeper than 1 % "
        "| not all arrived "
        "| limit violations | collision rate upper 95 % | intrusion rate [95 % CI] "
        "| min d/r_pz | wall s | encounters/s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for family in families:  # ours, then RVO2-3D on the same encounters beside it
        for key in (family, f"{family}-rvo2"):
            if key in summaries:
                lines.append(summary_row(summaries[key]))
    bench = out_root / "throughput.md"
    if bench.exists():
        lines += ["", "## Throughput (`benchmarks/bench_sweep.py`)", "", bench.read_text().strip()]
    return "\n".join(lines) + "\n"


def check_options(args: argparse.Namespace, p: argparse.ArgumentParser) -> None:
    """Refuse ``-o`` without its own ``--out-root`` / ``--results`` or with a bad option,
    before anything runs."""
    from vo3d_opt.sim.scenario import ScenarioError, check_selector_options, parse_option

    defaults = p.parse_args([])
    if args.out_root == defaults.out_root or args.results == defaults.results:
        p.error("--selector-option: give the runs their own --out-root and --results")
    try:
        check_selector_options(dict(parse_option(o) for o in args.selector_option), "-o")
    except ScenarioError as exc:
        p.error(str(exc))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", nargs="+", default=["10000"], help="N, or FAMILY=N items")
    p.add_argument("--families", nargs="+", default=list(FAMILIES))
    p.add_argument("--rvo2", nargs="*", default=list(RVO2), help="families also flown by RVO2-3D")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out-root", type=Path, default=Path("/work/sweep-out"))
    p.add_argument("--stages", nargs="+", choices=("throughput", "sweeps", "table"),
                   default=["throughput", "sweeps", "table"])
    p.add_argument("--bench-family", default="pair")
    p.add_argument("--bench-n", type=int, default=300)
    p.add_argument("--results", type=Path, default=HERE / "results_sweeps.md")
    p.add_argument("--selector-option", "-o", action="append", default=[], metavar="KEY=VALUE",
                   help="passed to every vo3d sweep")
    args = p.parse_args(argv)
    if args.selector_option:
        check_options(args, p)

    if "throughput" in args.stages:
        throughput(args.bench_family, args.bench_n, args.seeds[0], args.out_root)
    if "sweeps" in args.stages:
        n = counts(args.n, args.families + args.rvo2)
        jobs = [(f, "vo3d") for f in args.families] + [(f, "rvo2") for f in args.rvo2]
        for seed in args.seeds:
            for family, method in jobs:
                run_one(family, n[family], seed=seed, workers=args.workers, method=method,
                        out=run_dir(args.out_root, family, method, seed),
                        options=args.selector_option)
    if "table" in args.stages:
        text = table(args.out_root, args.families, args.rvo2)
        args.results.write_text(text)
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
