"""``vo3d sweep FAMILY --n N``: N random encounters of a family on a Dask cluster, with rates
and Clopper-Pearson bounds (``vo3d_opt.sweep``; Dask and pandas load only here).

Exit status: 0 when every encounter ran (whatever its safety figures), 1 when some raised or
lost their worker (they are listed in the summary; the rest of the output is complete) or when
writing ``--out`` failed after the sweep (the summary is still printed), 2 with a one-line
message for a bad option (a selector option names its key), an unknown family, formulation or
solver, ``--method rvo2`` on a family with obstacles, or an unreachable scheduler.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vo3d_opt.extras import check
from vo3d_opt.selector import DEFAULT_NLP_SOLVER, DEFAULT_QP_SOLVER, FORMULATIONS
from vo3d_opt.sim.scenario import ScenarioError, check_selector_options
from vo3d_opt.sim.simulator import DEFAULT_FORMULATION
from vo3d_opt.sweep.store import FLUSH_SECONDS, ResumeError, check_out

from .common import (
    EXIT_INTERRUPTED,
    EXIT_OK,
    UsageError,
    add_selector_options,
    non_negative_int,
    out_dir,
    positive_int,
    stdout_to_stderr,
)

if TYPE_CHECKING:
    from vo3d_opt.sweep.runner import Method, SweepResult

EXIT_ERRORS = 1

log = logging.getLogger("vo3d_opt.sweep")


def positive_float(text: str) -> float:
    """An argparse ``type``: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def _cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def add_sweep_parser(sub: Any, common: list[argparse.ArgumentParser]) -> None:
    sw = sub.add_parser(
        "sweep",
        parents=common,
        help="run N random encounters of a family on Dask",
        description="Run N random encounters of a family on a Dask cluster and report rates with "
        "95% Clopper-Pearson bounds. Exit status 0 when every encounter ran, 1 when "
        "some raised or lost their worker (listed in the summary) or writing --out failed, "
        "2 for bad options.",
    )
    sw.add_argument("family", nargs="?", help="encounter family (vo3d sweep --list names them)")
    sw.add_argument("--list", action="store_true", help="list the families, one line each")
    sw.add_argument(
        "--n", type=positive_int, metavar="N", help="number of encounters (1 to 10,000,000)"
    )
    sw.add_argument(
        "--seed",
        type=non_negative_int,
        default=0,
        metavar="S",
        help="sweep seed (0 to 2**63 - 1, default 0); encounter i is drawn from (S, i)",
    )
    where = sw.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=positive_int,
        metavar="K",
        default=_cpus(),
        help="local Dask worker processes, one thread each (default: the CPUs; at most four "
        "per CPU, or 8)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="use the existing Dask scheduler at ADDRESS (tcp://HOST:PORT or tls://HOST:PORT)",
    )
    sw.add_argument(
        "--method",
        choices=("vo3d", "rvo2", "none"),
        default="vo3d",
        help="vo3d (default); rvo2: RVO2-3D, obstacle-free families only; none: no avoidance, "
        "every agent straight to its goal (the unmitigated rates, for risk ratios)",
    )
    sw.add_argument(
        "--formulation",
        "-f",
        metavar="F",
        help=f"{' | '.join(FORMULATIONS)}; default: {DEFAULT_FORMULATION}",
    )
    sw.add_argument(
        "--solver",
        "-s",
        metavar="S",
        help="solver names as for `vo3d run --solver`; default: "
        f"{DEFAULT_QP_SOLVER} (QP) / {DEFAULT_NLP_SOLVER} (nlp)",
    )
    add_selector_options(sw, "every encounter (--method vo3d)", default="safe")
    sw.add_argument(
        "--out",
        metavar="DIR",
        help="keep the rows in DIR as they come (resumable), and write encounters.parquet, "
        "min_distance.png, failures/*.yaml (replayable by vo3d run) and summary.json there "
        "at the end (created; checked before the sweep)",
    )
    sw.add_argument(
        "--against",
        metavar="DIR",
        help="the --out DIR of the same sweep flown with --method none: the summary then "
        "gives the risk ratios of collisions and intrusions against it",
    )
    sw.add_argument(
        "--resume",
        action="store_true",
        help="continue the sweep in --out DIR (the same arguments): fly only the encounters "
        "missing there",
    )
    sw.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the sweep in --out DIR, finished or not (without it, or --resume, a "
        "directory holding a sweep is refused)",
    )
    sw.add_argument(
        "--json",
        action="store_true",
        help="print the summary as one JSON object on stdout (default: a table)",
    )
    sw.add_argument(
        "--in-flight",
        type=positive_int,
        metavar="M",
        help="encounters submitted at once (default 4 per worker, at least 8)",
    )
    sw.add_argument(
        "--batch",
        type=positive_int,
        metavar="B",
        help="encounters per Dask task (default: up to 64 for families flown side by side, else 1)",
    )
    sw.add_argument(
        "--flush-every",
        type=positive_float,
        metavar="SECONDS",
        default=FLUSH_SECONDS,
        help=f"with --out: write the rows flown to DIR at least this often (default "
        f"{FLUSH_SECONDS:g} s; what a killed sweep may have to fly again)",
    )
    sw.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    sw.set_defaults(func=cmd_sweep)


def cmd_sweep(args: argparse.Namespace) -> int:
    from vo3d_opt.sweep.runner import SweepError

    if args.out is not None and not args.list:
        out_dir(args.out)  # a bad --out fails before the sweep, not after it
    try:
        return _sweep(args)
    except SweepError as exc:
        raise UsageError(str(exc)) from None


def family_lines() -> list[str]:
    """One line per family: name, whether ``--method rvo2`` can fly it, summary."""
    from vo3d_opt.generators import FAMILIES

    width = max(len(name) for name in FAMILIES)
    return [
        f"{f.name:<{width}}  {'rvo2 ok  ' if f.obstacle_free else 'obstacles'}  {f.summary}"
        + (f" [needs scenario keys {', '.join(f.missing_keys())}]" if f.missing_keys() else "")
        for f in FAMILIES.values()
    ]


def _list(as_json: bool) -> int:
    from vo3d_opt.generators import FAMILIES

    if as_json:
        print(
            json.dumps(
                [
                    {
                        "name": f.name,
                        "description": f.summary,
                        "obstacle_free": f.obstacle_free,
                        "missing_keys": f.missing_keys(),
                    }
                    for f in FAMILIES.values()
                ]
            )
        )
    else:
        print("\n".join(family_lines()))
    return EXIT_OK


def _fmt(x: Any) -> str:
    if isinstance(x, dict):  # selector options, as -o takes them
        shown = (f"{k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in x.items())
        return " ".join(shown) or "-"
    if x is None:
        return "-"
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def format_summary(summary: dict[str, Any]) -> str:
    """The summary as a short table (the JSON has everything)."""
    keys = [
        "family",
        "method",
        "formulation",
        "solver",
        "selector_options",
        "seed",
        "encounters",
        "completed",
        "collisions",
        "encounters_with_collision",
        "pz_intrusions",
        "encounters_with_intrusion",
        "not_arrived",
        "limit_violations",
        "fallbacks",
        "min_normalised_distance",
        "collision_rate_upper95",
        "wall_time",
        "encounters_per_second",
        "workers",
    ]
    width = max(len(k) for k in keys)
    lines = [f"{k:<{width}}  {_fmt(summary.get(k))}" for k in keys]
    lines.append(
        "per-encounter rates: events/n, rate, two-sided 95% CI, one-sided upper 95% "
        "(Clopper-Pearson)"
    )
    for event, r in summary["rates"].items():
        if r["encounters"]:
            lo, hi = r["ci95"]
            lines.append(
                f"  {event:<16} {r['events']}/{r['encounters']}  {r['rate']:.4g}  "
                f"[{lo:.4g}, {hi:.4g}]  {r['upper95']:.4g}"
            )
    for event, r in (summary.get("risk_ratios") or {}).items():
        if r["ratio"] is None:
            lines.append(f"  risk ratio {event}: - (no {event} without avoidance)")
        else:
            lo, hi = r["ci95"]
            lines.append(
                f"  risk ratio {event}: {r['ratio']:.4g} [{lo:.4g}, {hi:.4g}] upper95 "
                f"{r['upper95']:.4g} ({r['events']}/{r['encounters']} against "
                f"{r['events_without_avoidance']}/{r['encounters_without_avoidance']} "
                "without avoidance; Koopman score interval)"
            )
    for err in summary["errors"]:
        lines.append(f"error in encounter {err['index']}: {err['error']}")
    return "\n".join(lines)


def _without_avoidance(folder: str, family: str, n: int, seed: int) -> dict[str, Any]:
    """The summary of the finished ``--method none`` sweep of ``family``, ``n`` and ``seed``
    in ``folder`` (for ``--against``), checked before anything flies."""
    from vo3d_opt.sweep.runner import SweepError

    path = Path(folder) / "summary.json"
    try:
        summary = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SweepError(f"--against {folder}: no finished sweep there ({exc})") from None
    if not isinstance(summary, dict) or summary.get("method") != "none":
        raise SweepError(f"--against {folder}: not a --method none sweep")
    for key, value in (("family", family), ("encounters", n), ("seed", seed)):
        if summary.get(key) != value:
            raise SweepError(f"--against {folder}: {key} {summary.get(key)!r}, not {value!r}")
    return summary


def _run(args: argparse.Namespace, workers: int, method: Method) -> SweepResult:
    """``run_sweep`` with the command line's arguments."""
    from vo3d_opt.sweep.runner import run_sweep

    with stdout_to_stderr():  # worker processes inherit the redirected descriptor too
        return run_sweep(
            args.family,
            args.n,
            seed=args.seed,
            workers=workers,
            scheduler=args.scheduler,
            method=method,
            in_flight=args.in_flight,
            progress=not args.no_progress and log.isEnabledFor(logging.INFO),
            out=args.out,
            resume=args.resume,
            overwrite=args.overwrite,
            batch=args.batch,
            flush_seconds=args.flush_every,
        )


def _local(workers: int) -> str:
    return f"{workers} local worker" + ("" if workers == 1 else "s")


def _method(args: argparse.Namespace) -> Method:
    """The method the command line names, its selector options checked."""
    from vo3d_opt.sweep.runner import Method, SweepError

    try:
        options = check_selector_options(dict(args.selector_options or ()), "--selector-option")
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None
    return Method(
        name=args.method,
        formulation=args.formulation,
        solver=args.solver,
        selector_options=tuple(options.items()),
    )


def _check_flags(args: argparse.Namespace) -> None:
    """The arguments that need others, refused before anything else is looked at."""
    from vo3d_opt.sweep.runner import SweepError

    if not args.family:
        raise SweepError("family: required (vo3d sweep --list names them)")
    if args.n is None:
        raise SweepError("--n: required (the number of encounters)")
    for flag, given in (("--resume", args.resume), ("--overwrite", args.overwrite)):
        if given and args.out is None:
            raise SweepError(f"{flag}: needs --out DIR (the directory of the sweep)")
    if args.resume and args.overwrite:
        raise SweepError("--resume, --overwrite: give one of them")


def _check_start(args: argparse.Namespace, method: Method) -> int:
    """Everything a sweep can be refused for, checked before its first line is logged (so a
    refusal is the only line): the scheduler reachable, the counts, the --out directory. The
    local workers to start."""
    from vo3d_opt.sweep.cluster import ConnectError, check_address, check_reachable
    from vo3d_opt.sweep.runner import SweepError, manifest, validate

    if args.scheduler is not None:
        try:
            check_address(args.scheduler)
            check_reachable(args.scheduler)
        except ConnectError as exc:
            raise SweepError(f"--scheduler: {exc}") from None
    workers = 1 if args.workers is None and args.scheduler else args.workers
    fam, formulation, solver = validate(
        args.family,
        args.n,
        seed=args.seed,
        workers=workers,
        method=method,
        in_flight=args.in_flight,
        batch=args.batch,
    )
    if args.out is not None:
        try:
            key = manifest(fam, args.n, args.seed, method, formulation, solver)
            check_out(args.out, key, resume=args.resume, overwrite=args.overwrite)
        except ResumeError as exc:
            raise SweepError(str(exc)) from None
    return int(workers)


def _sweep(args: argparse.Namespace) -> int:
    """Run ``vo3d sweep`` with its parsed ``args``; progress is logged (``vo3d_opt.sweep``
    logger, shown on stderr) and native code's prints are kept off stdout (the JSON's)."""
    from vo3d_opt.sweep.runner import SweepError
    from vo3d_opt.sweep.stats import risk_ratios

    if args.list:
        return _list(args.json)
    check("sweep", "the sweep command")  # before anything is said: one line if it is missing
    _check_flags(args)
    without = None
    if args.against is not None:
        without = _without_avoidance(args.against, args.family, args.n, args.seed)
    method = _method(args)
    workers = _check_start(args, method)
    log.info(
        "sweep %s: %d encounters, seed %d, method %s, %s",
        args.family,
        args.n,
        args.seed,
        args.method,
        f"scheduler {args.scheduler}" if args.scheduler else _local(workers),
    )
    try:
        result = _run(args, workers, method)
    except KeyboardInterrupt:
        if args.out is None:
            raise
        log.error(
            "interrupted: the encounters flown are kept in %s; the same command with --resume "
            "(and without --overwrite) flies the rest",
            args.out,
        )
        return EXIT_INTERRUPTED
    s = result.summary
    if without is not None:
        try:
            s["risk_ratios"] = risk_ratios(s, without)
        except ValueError as exc:
            raise SweepError(f"--against {args.against}: {exc}") from None
    status = _write(result, args.out)
    _log_done(result)
    print(json.dumps(s, allow_nan=False) if args.json else format_summary(s))
    return status


def _write(result: SweepResult, out: str | None) -> int:
    """``result``'s files into ``out`` (if given); the exit status: EXIT_ERRORS when some
    encounters raised or writing failed (the summary is printed all the same)."""
    status = EXIT_ERRORS if result.summary["errors"] else EXIT_OK
    if out is not None:
        from vo3d_opt.sweep.output import write_results  # matplotlib only when asked for

        try:
            for path in write_results(result, Path(out)):
                log.info("wrote %s", path)
        except OSError as exc:  # the sweep is done: still print its summary
            log.error("--out %s: writing failed: %s", out, exc.strerror or exc)
            status = EXIT_ERRORS
    return status


def _log_done(result: SweepResult) -> None:
    s = result.summary
    log.info(
        "done: %d encounters flown in %.1f s (+%.1f s cluster and warm-up), %d found in --out; "
        "%d/%d completed, %d errors",
        result.flown,
        s["wall_time"],
        s["setup_time"],
        s["encounters"] - result.flown,
        s["completed"],
        s["encounters"],
        len(s["errors"]),
    )
