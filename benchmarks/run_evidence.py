"""The evidence sweeps: every family flown with our method, RVO2-3D where it can fly and no
avoidance, resumable across sittings, and one results page per family.

    python benchmarks/run_evidence.py [--n 100000] [--n-rotorpy 1000]
        [--families pair group dense lagged noisy intruder rotorpy] [--methods none vo3d rvo2]
        [--workers 2 |
        --scheduler tcp://HOST:8786] [--out-root /work/evidence] [--pages docs/results/sweeps]
        [--stages sweeps pages]

Stage ``sweeps``: for each family, ``vo3d sweep FAMILY --n N --seed 0 --method none``, then
``--method vo3d`` (the default preset) and, for the obstacle-free families, ``--method rvo2``,
each with ``--against`` the sweep without avoidance (risk ratios) and ``--resume``: run the
script again after any interruption and each sweep flies only what it is missing (a finished
one only rewrites its outputs). Each sweep writes into ``OUT_ROOT/FAMILY/METHOD`` and its
progress into ``sweep.log`` there.

Stage ``pages``: ``PAGES/FAMILY.md`` from the finished sweeps (machine, date and commit once
at the top): per method the rates with Clopper–Pearson bounds, the risk ratios against no
avoidance (Koopman score intervals), the wall time per 1,000 encounters, the figure of the
closest approach per method (``PAGES/FAMILY.png``), and every encounter our method failed as
a scenario file that ``vo3d run`` replays (copied to ``PAGES/FAMILY/``).
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from pages import RESULTS, commit, machine_line, write_page
from run_sweeps import vo3d_cmd, vo3d_sweep  # this folder's

FAMILIES = ("pair", "group", "dense", "lagged", "noisy", "intruder", "rotorpy")
RVO2 = ("pair", "dense")  # the obstacle-free families: RVO2-3D flies them
#: The order of the runs of a family: none first (the others' risk ratios need it).
METHODS = ("none", "vo3d", "rvo2")
NAMES = {"vo3d": "vo3d (ours, preset safe)", "rvo2": "RVO2-3D", "none": "no avoidance"}
#: Each sweep directory's record of its sittings: "COMMIT ENCOUNTERS_FLOWN", one line each.
COMMITS = "commits.txt"
#: The preset our method flies (``--preset``; the pages name it).
PRESET = {"name": "safe"}
#: What a family's page says below its table, beyond the rates.
NOTES = {
    "rotorpy": [
        "A limit violation here is a speed violation of the vehicle: its true speed, sampled "
        "at every RotorPy sub-step, above its top speed. RotorPy's velocity loop overshoots a "
        "command held at the top speed in wind, so under RotorPy in wind our method plans "
        "0.1 m/s below it ([what that margin buys](rotorpy-speed.md), "
        "`benchmarks/speed_overshoot.py`); without avoidance the vehicles fly straight at their "
        "top speed.",
        "",
        "Encounter 960, a vehicle skimming the top of a cylinder's planning prism that lags a "
        "small climb and ends 2 mm inside it, entered the obstacle's zone on `400cae0` (inside "
        "a prism only a horizontal approach closed in, so the least-bad velocity braked and "
        "sank, 1.36 m from the surface of a 2 m zone). Under a prism's top a descent now closes "
        "in too: it flies clean (`tests/test_sweep_failures.py`).",
        "",
    ],
}


def methods_of(family: str) -> list[str]:
    return [m for m in METHODS if m != "rvo2" or family in RVO2]


def finished(out: Path, n: int) -> dict | None:
    """The summary of the sweep in ``out`` if it flew all of its ``n`` encounters, else None."""
    path = out / "summary.json"
    if not path.exists():
        return None
    summary = json.loads(path.read_text())
    return summary if summary.get("encounters") == n and summary.get("completed") == n else None


def run_one(family: str, method: str, n: int, out_root: Path, where: list[str]) -> dict:
    """One resumable ``vo3d sweep``; its summary. A sweep already finished is left as it is (a
    resume would write its outputs again, 90,000 failure files for a family without avoidance,
    and put this sitting's timing, none, in its summary)."""
    out = out_root / family / method
    done = finished(out, n)
    if done is not None:
        print(f"  {family} {method}: {n} encounters, finished before", file=sys.stderr, flush=True)
        return done
    out.mkdir(parents=True, exist_ok=True)
    cmd = vo3d_cmd() + ["sweep", family, "--n", str(n), "--seed", "0", "--method", method,
                        "--out", str(out), "--json", "--resume", *where]
    if method != "none" and (out_root / family / "none" / "summary.json").exists():
        cmd += ["--against", str(out_root / family / "none")]
    if method == "vo3d" and PRESET["name"] != "safe":
        cmd += ["--preset", PRESET["name"]]
    code, t0 = commit(), time.perf_counter()
    summary = vo3d_sweep(cmd, out, f"{family} ({method})", log_mode="a")
    flown = _logged(out)[-1][0] if _logged(out) else 0
    if flown:  # the page names the code of every sitting that flew encounters
        with (out / COMMITS).open("a") as f:
            f.write(f"{code} {flown}\n")
    print(f"  {family} {method}: {summary['encounters']} encounters, this sitting "
          f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return summary


# ------------------------------------------------------------------------------ the pages


def _pct(x: float | None) -> str:
    return "-" if x is None else (f"{x:.2e}" if 0 < x < 1e-3 else f"{x:.4%}")


def _rate(r: dict[str, Any]) -> str:
    lo, hi = r["ci95"]
    return f"{r['events']} ({_pct(r['rate'])}; 95 % CI [{_pct(lo)}, {_pct(hi)}]; " \
           f"upper 95 % {_pct(r['upper95'])})"


def _ratio(r: dict[str, Any] | None) -> str:
    if r is None or r["ratio"] is None:
        return "- (no event without avoidance)"
    lo, hi = r["ci95"]
    return f"{r['ratio']:.3g} (95 % CI [{lo:.3g}, {hi:.3g}]; upper 95 % {r['upper95']:.3g})"


def _logged(out: Path) -> list[tuple[int, float]]:
    """(encounters flown, seconds) of each sitting that reached its last log line."""
    log = out / "sweep.log"
    if not log.exists():
        return []
    return [(int(line.split()[1]), float(line.split(" in ", 1)[1].split(" s", 1)[0]))
            for line in log.read_text(errors="replace").splitlines()
            if line.startswith("done:") and " in " in line]


def _sittings(out: Path, encounters: int) -> float | None:
    """Seconds of flight over every sitting, from the sweep's log lines; None when the logged
    sittings did not fly every encounter (one was stopped before its last line)."""
    done = _logged(out)
    return sum(s for _, s in done) if sum(k for k, _ in done) == encounters else None


def flown_on(found: dict[str, Path]) -> list[str]:
    """The commit of each method's sittings and how many encounters each flew (run_one's
    record), and whether the record covers every encounter."""
    if not found:
        return []
    lines = ["Flown on (the commit of each sitting, with the encounters it flew):", ""]
    for method, out in found.items():
        path = out / COMMITS
        # "<commit> <encounters>", the commit possibly "<hash> + uncommitted changes"
        entries = [line.rsplit(maxsplit=1) for line in path.read_text().splitlines()
                   if line.strip()] if path.exists() else []
        total = json.loads((out / "summary.json").read_text())["encounters"]
        recorded = sum(int(k) for _, k in entries)
        text = ", ".join(f"`{c}` ({int(k):,})" for c, k in entries) or "commit not recorded"
        if entries and recorded != total:
            text += f"; {total - recorded:,} more in sittings that did not record theirs"
        lines.append(f"- {NAMES[method]}: {text}")
    return [*lines, ""]


def method_rows(family: str, out_root: Path) -> tuple[list[str], dict[str, Path]]:
    lines = [
        "| method | encounters | errors | collisions | intrusions | not all arrived | "
        "limit violations | min d / r_pz | risk ratio, collisions | risk ratio, intrusions | "
        "flight s per 1,000 (-: a sitting stopped unlogged) |",
        "|---|---:|---:|---|---|---:|---:|---:|---|---|---:|",
    ]
    found = {}
    for method in methods_of(family):
        out = out_root / family / method
        if not (out / "summary.json").exists():
            lines.append(f"| {NAMES[method]} | not flown yet | | | | | | | | | |")
            continue
        found[method] = out
        s = json.loads((out / "summary.json").read_text())
        r, rr = s["rates"], s.get("risk_ratios", {})
        flight = _sittings(out, s["encounters"])
        per_k = "-" if flight is None else f"{1000 * flight / max(1, s['encounters']):.0f}"
        lines.append(
            f"| {NAMES[method]} | {s['encounters']:,} | {len(s['errors'])} | "
            f"{_rate(r['collision'])} | {_rate(r['intrusion'])} | "
            f"{s['encounters_not_all_arrived']} | {r['limit_violation']['events']} | "
            f"{s['min_normalised_distance']:.3f} | "
            f"{'-' if method == 'none' else _ratio(rr.get('collision'))} | "
            f"{'-' if method == 'none' else _ratio(rr.get('intrusion'))} | {per_k} |"
        )
    return lines, found


def failures_section(family: str, found: dict[str, Path], pages: Path) -> list[str]:
    """Our method's failing encounters, copied beside the page, with the replay command."""
    lines = ["## Encounters our method failed", ""]
    if "vo3d" not in found:
        return lines + ["(not flown yet)", ""]
    folder = pages / family
    shutil.rmtree(folder, ignore_errors=True)
    files = sorted((found["vo3d"] / "failures").glob("*.yaml"))
    if not files:
        lines.append("None: no collision, intrusion, agent short of its goal or limit broken in "
                     "any encounter.")
    else:
        folder.mkdir(parents=True)
        lines += [f"{len(files)} encounter{'s' if len(files) > 1 else ''}; each replays with "
                  "`vo3d run FILE --json`:", ""]
    for path in files:
        shutil.copy(path, folder / path.name)
        why = path.read_text().splitlines()[0].lstrip("# ")
        lines.append(f"* [{path.name}]({family}/{path.name}): {why}")
    others = {m: len(list((out / "failures").glob("*.yaml"))) for m, out in found.items()
              if m != "vo3d"}
    if others:
        lines += ["", "Failing encounters of the other methods (in their sweep directories): "
                  + ", ".join(f"{NAMES[m]} {k:,}" for m, k in others.items()) + "."]
    return lines + [""]


def page(family: str, out_root: Path, pages: Path) -> str:
    import pandas as pd

    from vo3d_opt.sweep.output import plot_closest_approach

    table, found = method_rows(family, out_root)
    lines = [
        f"# Sweep results: `{family}`",
        "",
        machine_line(),
        "",
        "`python benchmarks/run_evidence.py`, seed 0 (encounter i of every method is the same "
        "encounter).",
        "",
        "Rates are per encounter (an encounter counts once however many pairs collided or "
        "intruded), with two-sided 95 % Clopper–Pearson intervals and the one-sided 95 % upper "
        "bound. Risk ratios: the method's rate over the rate of the same encounters flown "
        "without avoidance (every agent straight to its goal), with Koopman's score interval "
        "for a ratio of two binomial proportions (statsmodels), which stays defined when the "
        "method has no event; the encounters are the same, so the outcomes are positively "
        "correlated and this interval for independent samples is the conservative one. "
        "min d / r_pz: the closest approach of any pair over all encounters, in the pair's "
        "larger protected-zone radius (below 1: an intrusion).",
        "",
        *table,
        "",
        *NOTES.get(family, []),
    ]
    lines += flown_on(found)
    if found:
        figure = pages / f"{family}.png"
        runs = {m: pd.read_parquet(out / "encounters.parquet") for m, out in found.items()}
        plot_closest_approach(family, runs, figure)
        lines += [f"![closest approach per encounter, {family}]({figure.name})", ""]
    lines += failures_section(family, found, pages)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=100_000)
    p.add_argument("--n-rotorpy", type=int, default=1000)
    p.add_argument("--families", nargs="+", default=list(FAMILIES))
    p.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS),
                   help="of each family's methods, fly these (none first: the risk ratios)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int)
    where.add_argument("--scheduler")
    p.add_argument("--out-root", type=Path, default=Path("/work/evidence"))
    p.add_argument("--pages", type=Path, default=RESULTS / "sweeps")
    p.add_argument("--stages", nargs="+", choices=("sweeps", "pages"), default=["sweeps", "pages"])
    p.add_argument("--preset", default="safe",
                   help="the preset our method flies (then give its own --out-root and --pages)")
    args = p.parse_args(argv)
    PRESET["name"] = args.preset
    NAMES["vo3d"] = f"vo3d (ours, preset {args.preset})"
    place = (["--scheduler", args.scheduler] if args.scheduler else
             ["--workers", str(args.workers)] if args.workers else [])
    if "sweeps" in args.stages:
        for family in args.families:
            n = args.n_rotorpy if family == "rotorpy" else args.n
            for method in (m for m in methods_of(family) if m in args.methods):
                run_one(family, method, n, args.out_root, place)
    if "pages" in args.stages:
        args.pages.mkdir(parents=True, exist_ok=True)
        for family in args.families:
            path = args.pages / f"{family}.md"
            write_page(path, page(family, args.out_root, args.pages))
            print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
