"""The evidence sweeps: every family's rates, ours and RVO2-3D's, in one table.

Three stages (all by default, or those named with ``--stages``):

* ``throughput``: encounters per second of the same ``--bench-n`` encounters of
  ``--bench-family`` with 1 and 2 workers (``bench_sweep.py``), written to
  ``OUT_ROOT/throughput.md``;
* ``sweeps``: ``vo3d sweep FAMILY --n N --seed S --workers K --out OUT_ROOT/FAMILY --json`` for
  every family of ``--families``, and ``--method rvo2`` into ``OUT_ROOT/FAMILY-rvo2`` for every
  family of ``--rvo2`` (obstacle-free ones: the same encounters), each as its own process;
  with several ``--seeds``, seed 0 goes there and seed S into ``.../seedS``;
* ``table``: the whole page ``docs/results/sweeps.md`` from the runs found under ``OUT_ROOT``
  and ``throughput.md`` (so the page can be rebuilt without flying anything), one section per
  configuration: ``OUT_ROOT``'s, then those of ``--also OUT_ROOT ...`` (runs flown with other
  ``--selector-option``). The runs of one family and method with different seeds are
  independent encounters (the stream of encounter i is seeded by (seed, i)): their rows are
  pooled into one line, rates and bounds recomputed. Each run records the machine line and
  commit it flew at (``machine.json``); the page names them, and refuses runs of several
  commits.

    python benchmarks/run_sweeps.py --n 10000 [--families pair group dense lagged]
        [--rvo2 pair dense] [--seeds 0] [--workers 2] [--out-root /work/sweep-out]
        [--stages throughput sweeps table] [--results docs/results/sweeps.md]
        [--also OUT_ROOT ...]
        [--selector-option KEY=VALUE ...]

``--n`` is one N for every family, or ``FAMILY=N`` items for per-family counts.
``--selector-option`` passes ``-o KEY=VALUE`` to every ``vo3d`` sweep (not RVO2-3D's nor the
throughput stage's); the table names the options beside the method. Such runs need their own
``--out-root`` and ``--results`` (refused without them: they would overwrite the defaults').
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from pages import RESULTS, commit, machine_line, write_page

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
        if any(own_options(x) != own_options(first) for x in summaries):
            raise SystemExit(f"{dirs}: the seeds ran with different selector options")
        s.update({"seed": [x["seed"] for x in summaries], "wall_time": wall,
                  "selector_options": own_options(first),
                  "encounters_per_second": s["encounters"] / wall, "workers": first["workers"]})
    s["deep_intrusions"] = int((rows["min_normalised_distance"] < DEEP).sum())
    return s


def own_options(summary: dict[str, Any]) -> dict[str, Any]:
    """A summary's selector options but the default preset (summaries before it was named
    there have none)."""
    options = summary.get("selector_options") or {}
    return {k: v for k, v in options.items() if (k, v) != ("preset", "safe")}


def vo3d_sweep(cmd: list[str], out: Path, what: str, log_mode: str = "w") -> dict[str, Any]:
    """Run one ``vo3d sweep`` command, its stderr (progress) into ``out/sweep.log`` (``"a"``:
    appended to it); its JSON summary."""
    print(" ".join(cmd), file=sys.stderr, flush=True)
    with open(out / "sweep.log", log_mode) as log:
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=log, text=True)
    if proc.returncode not in (0, 1):  # 1: some encounters raised (listed in the summary)
        raise SystemExit(f"{what}: exit status {proc.returncode}, see {out}/sweep.log")
    return json.loads(proc.stdout)


def run_one(family: str, n: int, *, seed: int, workers: int, method: str, out: Path,
            options: list[str]) -> None:
    """One ``vo3d sweep`` process; its stderr (progress) goes to ``out/sweep.log``."""
    out.mkdir(parents=True, exist_ok=True)
    cmd = vo3d_cmd() + ["sweep", family, "--n", str(n), "--seed", str(seed), "--workers",
                        str(workers), "--method", method, "--out", str(out), "--json",
                        "--overwrite"]  # a new flight: whatever an earlier run left there
    if method == "vo3d":
        cmd += [arg for option in options for arg in ("-o", option)]
    t0 = time.perf_counter()
    summary = vo3d_sweep(cmd, out, f"{family} ({method})")
    (out / "command.txt").write_text(" ".join(cmd) + "\n")
    (out / "machine.json").write_text(json.dumps({"machine": machine_line(), "commit": commit()}))
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


def method_label(s: dict[str, Any]) -> str:
    options = ", ".join(f"{k}: {json.dumps(v)}" for k, v in own_options(s).items())
    label = "plane_qp" + (f"; {options}" if options else "")
    return f"ours ({label})" if s["method"] == "vo3d" else "RVO2-3D"


def summary_row(s: dict[str, Any]) -> str:
    r = s["rates"]
    fallbacks = (f"{r['fallback']['events']} ({s['fallbacks']})" if "fallback" in r
                 else "–")  # RVO2-3D has none
    return (f"| {s['family']} | {method_label(s)} | {s['encounters']} | {len(s['errors'])} | "
            f"{s['encounters_with_collision']} ({s['collisions']}) | "
            f"{s['encounters_with_intrusion']} ({s['pz_intrusions']}) | {s['deep_intrusions']} | "
            f"{s['encounters_not_all_arrived']} ({s['not_arrived']}) | "
            f"{r['limit_violation']['events']} ({s['limit_violations']}) | "
            f"{fallbacks} | "
            f"{_pct(s['collision_rate_upper95'])} | {_rate(r['intrusion'])} | "
            f"{s['min_normalised_distance']:.3f} | {s['wall_time']:.0f} | "
            f"{s['encounters_per_second']:.2f} |")


TABLE = ("| family | method | N | errors | collisions | intrusions | deeper than 1 % "
         "| not all arrived | limit violations | fallbacks | collision rate upper 95 % "
         "| intrusion rate [95 % CI] | min d/r_pz | wall s | encounters/s |\n"
         "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
COUNTS = ("Counts are encounters (and events in brackets: vehicle pairs for collisions and "
          "intrusions, agents for not arrived, samples for limit violations, decisions for "
          "fallbacks). Rates per encounter with Clopper–Pearson bounds: collision one-sided upper "
          "95 %, intrusion two-sided 95 % CI. min d/r_pz: the smallest closest approach over the "
          "larger protected-zone radius of the pair, over all encounters; \"deeper than 1 %\": "
          f"encounters where it fell below {DEEP} (vehicle pairs). RVO2-3D flies the same "
          "encounters (obstacle-free families only), every agent with radius max(r_pz)/2.")


def run_dirs(path: Path) -> list[Path]:
    """A run's directory and its other seeds' (``seedS``), those that finished."""
    return [d for d in [path, *sorted(path.glob("seed*"))] if (d / "summary.json").exists()]


def _events(s: dict[str, Any]) -> str:
    said = [f"{s['encounters_with_collision']} with a collision",
            f"{s['encounters_with_intrusion']} with an intrusion",
            f"{s['encounters_not_all_arrived']} with an agent short of its goal",
            f"{s['rates']['limit_violation']['events']} with a limit broken",
            f"{len(s['errors'])} that raised"]
    return ", ".join(x for x in said if not x.startswith("0 "))


def findings(summaries: dict[str, dict[str, Any]]) -> list[str]:
    """Ours family by family, and RVO2-3D beside it."""
    ours = {s["family"]: s for s in summaries.values() if s["method"] == "vo3d"}
    clean = [f"`{f}`" for f, s in ours.items() if not _events(s)]
    out = []
    if clean:
        out.append(f"- Ours: no collision, no intrusion, every agent home, no limit broken and no "
                   f"error in any encounter of {', '.join(clean)}.")
    out += [f"- Ours, `{f}`: of {s['encounters']:,} encounters {_events(s)}."
            for f, s in ours.items() if _events(s)]
    for s in summaries.values():
        if s["method"] != "vo3d":
            r = s["rates"]["intrusion"]
            out.append(f"- {method_label(s)} on the same encounters of `{s['family']}`: an "
                       f"intrusion in {r['rate']:.2%} of them ({s['deep_intrusions']:,} deeper "
                       f"than 1 %), {s['encounters_with_collision']:,} with a collision.")
    return out


def provenance(dirs: list[Path]) -> list[str]:
    """The command of each run (its ``command.txt``) and its wall time."""
    out = []
    for d in dirs:
        words = (d / "command.txt").read_text().split() if (d / "command.txt").exists() else []
        if words[1:3] == ["-m", "vo3d_opt.cli"]:
            words = ["vo3d", *words[3:]]
        elif words:
            words[0] = Path(words[0]).name
        if "--out" in words:  # a directory of this machine's, not the page's business
            k = words.index("--out")
            del words[k:k + 2]
        wall = json.loads((d / "summary.json").read_text())["wall_time"]
        out.append(f"- `{' '.join(words) or '?'}` ({wall:.0f} s)")
    return out


def section(out_root: Path, families: list[str], rvo2: list[str]) -> tuple[list[str], list[Path]]:
    """One configuration's table (the runs under ``out_root``), its findings and its runs."""
    runs = [out_root / f for f in families] + [out_root / f"{f}-rvo2" for f in rvo2]
    summaries, dirs = {}, []
    for path in runs:
        found = run_dirs(path)
        if found:
            summaries[path.name] = pooled(found)
            dirs += found
        else:
            print(f"missing {path}/summary.json: left out of the table", file=sys.stderr)
    first = next(iter(summaries.values()), {})
    seeds = sorted({x for s in summaries.values()
                    for x in (s["seed"] if isinstance(s["seed"], list) else [s["seed"]])})
    options = next((own_options(s) for s in summaries.values() if s["method"] == "vo3d"), {})
    title = ("With the defaults (the `safe` preset)" if not options else "With " + ", ".join(
        f"`-o {k}={json.dumps(v)}`" for k, v in options.items()))
    lines = [f"## {title}", "", f"Seeds {', '.join(map(str, seeds))} (encounters 0..N_seed-1 of "
             f"each), {first.get('workers', '?')} local Dask workers.", "", TABLE]
    for family in families:  # ours, then RVO2-3D on the same encounters beside it
        lines += [summary_row(summaries[k]) for k in (family, f"{family}-rvo2") if k in summaries]
    lines += ["", *findings(summaries), "", "Runs:", "", *provenance(dirs), ""]
    return lines, dirs


def page_machine(dirs: list[Path]) -> str:
    """The machine line the runs recorded (the last one's), when every run flew one commit;
    without records, this machine now."""
    files = [d / "machine.json" for d in dirs if (d / "machine.json").exists()]
    records = [json.loads(f.read_text()) | {"mtime": f.stat().st_mtime} for f in files]
    commits = sorted({r["commit"] for r in records})
    if len(commits) > 1:
        raise SystemExit(f"the runs were flown at several commits ({', '.join(commits)}): a page "
                         "names one; fly them again or give them pages of their own")
    if not records or len(records) < len(dirs):
        print("some runs recorded no machine line: the page takes this machine's, now",
              file=sys.stderr)
        return machine_line()
    return max(records, key=lambda r: r["mtime"])["machine"]


def throughput_section(bench: Path) -> list[str]:
    """bench_sweep.py's page of the throughput stage, its headings one level down and its own
    title and machine line left out (the runs share this page's)."""
    body = bench.read_text().splitlines()
    start = next((i for i, line in enumerate(body) if line.startswith("`")), len(body))
    return ["## Throughput (`benchmarks/bench_sweep.py`)", "",
            *("#" + line if line.startswith("#") else line for line in body[start:])]


def table(out_roots: list[Path], families: list[str], rvo2: list[str]) -> str:
    sections, dirs = [], []
    for out_root in out_roots:
        lines, found = section(out_root, families, rvo2)
        sections += lines
        dirs += found
    bench = out_roots[0] / "throughput.md"
    if bench.exists():
        sections += throughput_section(bench)
    head = ["# Monte Carlo sweeps", "", page_machine(dirs), "",
            "`python benchmarks/run_sweeps.py`: each section one configuration flown over the "
            "same encounters (`vo3d sweep`, one process a family and method; each section lists "
            "its runs).", "", COUNTS, ""]
    return "\n".join(head + sections)


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
    p.add_argument("--results", type=Path, default=RESULTS / "sweeps.md")
    p.add_argument("--also", type=Path, nargs="*", default=[], metavar="OUT_ROOT",
                   help="table stage: the runs of other configurations (e.g. flown with -o "
                        "under another --out-root), each a section of the page")
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
        text = table([args.out_root, *args.also], args.families, args.rvo2)
        write_page(args.results, text)
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
