"""``vo3d sweep``: what the command does with its parsed options (the options themselves are
declared in ``vo3d_opt.cli``).

Exit status: 0 when every encounter ran (whatever its safety figures), 1 when some raised or
lost their worker (they are listed in the summary; the rest of the output is complete) or when
writing ``--out`` failed after the sweep (the summary is still printed), 2 with a one-line
message (:class:`~vo3d_opt.sweep.runner.SweepError`) for a bad option (a selector option names
its key), an unknown family, formulation or solver, ``--method rvo2`` on a family with
obstacles, or an unreachable scheduler.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vo3d_opt.sim.scenario import ScenarioError, check_selector_options
from vo3d_opt.sweep.families import FAMILIES
from vo3d_opt.sweep.runner import Method, SweepError, run_sweep, validate

EXIT_OK, EXIT_ERRORS = 0, 1

log = logging.getLogger(__name__)


def family_lines() -> list[str]:
    """One line per family: name, whether ``--method rvo2`` can fly it, summary."""
    width = max(len(name) for name in FAMILIES)
    return [
        f"{f.name:<{width}}  {'rvo2 ok  ' if f.obstacle_free else 'obstacles'}  {f.summary}"
        + (f" [needs scenario keys {', '.join(f.missing_keys())}]" if f.missing_keys() else "")
        for f in FAMILIES.values()
    ]


def _list(as_json: bool) -> int:
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
        return " ".join(f"{k}={json.dumps(v)}" for k, v in x.items()) or "-"
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
    for err in summary["errors"]:
        lines.append(f"error in encounter {err['index']}: {err['error']}")
    return "\n".join(lines)


def main(
    args: argparse.Namespace,
    *,
    protect_stdout: Callable[[], contextlib.AbstractContextManager[Any]],
) -> int:
    """Run ``vo3d sweep`` with its parsed ``args``; progress is logged (``vo3d_opt.sweep``
    logger, shown by the CLI on stderr) and ``protect_stdout`` keeps anything native code prints
    off stdout (the JSON's)."""
    if args.list:
        return _list(args.json)
    if not args.family:
        raise SweepError("family: required (vo3d sweep --list names them)")
    if args.n is None:
        raise SweepError("--n: required (the number of encounters)")
    try:
        options = check_selector_options(dict(args.selector_options or ()), "--selector-option")
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None
    method = Method(
        name=args.method,
        formulation=args.formulation,
        solver=args.solver,
        selector_options=tuple(options.items()),
    )
    workers = 1 if args.workers is None and args.scheduler else args.workers
    validate(
        args.family,
        args.n,
        seed=args.seed,
        workers=workers,
        method=method,
        in_flight=args.in_flight,
    )
    log.info(
        "sweep %s: %d encounters, seed %d, method %s, %s",
        args.family,
        args.n,
        args.seed,
        args.method,
        f"scheduler {args.scheduler}" if args.scheduler else f"{workers} local workers",
    )
    with protect_stdout():  # worker processes inherit the redirected descriptor too
        result = run_sweep(
            args.family,
            args.n,
            seed=args.seed,
            workers=workers,
            scheduler=args.scheduler,
            method=method,
            in_flight=args.in_flight,
            progress=not args.no_progress and log.isEnabledFor(logging.INFO),
        )
    s = result.summary
    status = EXIT_ERRORS if s["errors"] else EXIT_OK
    if args.out:
        from vo3d_opt.sweep.output import write_results  # matplotlib only when asked for

        try:
            for path in write_results(result, Path(args.out)):
                log.info("wrote %s", path)
        except OSError as exc:  # the sweep is done: still print its summary
            log.error("--out %s: writing failed: %s", args.out, exc.strerror or exc)
            status = EXIT_ERRORS
    log.info(
        "done: %d/%d encounters in %.1f s (+%.1f s cluster and warm-up), %d errors",
        s["completed"],
        s["encounters"],
        s["wall_time"],
        s["setup_time"],
        len(s["errors"]),
    )
    print(json.dumps(s, allow_nan=False) if args.json else format_summary(s))
    return status
