"""``vo3d run SCENARIO``: one scenario, every agent deciding for itself (the whole swarm in
one ``select_many`` call per step); a table by default, exactly one JSON object on stdout with
``--json``; ``--out DIR`` writes ``trajectories.parquet`` (and ``trajectories.csv`` up to
``report.CSV_MAX_ROWS`` rows), ``summary.json`` and the figures (``vo3d_opt.report``)."""

from __future__ import annotations

import argparse
import os
import tempfile
from typing import Any

from vo3d_opt.report import CSV_MAX_ROWS, write_outputs
from vo3d_opt.selector import DEFAULT_NLP_SOLVER, DEFAULT_QP_SOLVER, FORMULATIONS
from vo3d_opt.sim.record import check_allotment
from vo3d_opt.sim.scenario import Scenario
from vo3d_opt.sim.simulator import DEFAULT_FORMULATION
from vo3d_opt.sim.spill import in_memory_fs, spill_directory, spill_supported

from .common import (
    EXIT_FAIL,
    EXIT_OK,
    SCENARIO_HELP,
    UsageError,
    add_selector_options,
    load_or_exit,
    log,
    out_dir,
    positive_int,
    selector,
    to_json,
    with_options,
)
from .flight import fly_and_summarize, print_summary

SOLVER_HELP = (
    f"exact2d (plane_qp) | osqp | clarabel | daqp | cvxpy[:SOLVER] | qpsolvers:NAME | "
    f"casadi[:PLUGIN]; "
    f"default: the scenario's `solver`, else {DEFAULT_QP_SOLVER} for the QP "
    f"formulations and {DEFAULT_NLP_SOLVER} for nlp (sampled uses none)"
)


def add_run_parser(sub: Any, common: list[argparse.ArgumentParser]) -> None:
    run = sub.add_parser(
        "run",
        parents=common,
        help="run one scenario",
        description="Run one scenario, every agent deciding for itself.",
    )
    run.add_argument("scenario", help=SCENARIO_HELP)
    run.add_argument(
        "--formulation",
        "-f",
        metavar="F",
        help=f"{' | '.join(FORMULATIONS)}; default: the scenario's `formulation`, "
        f"else {DEFAULT_FORMULATION}",
    )
    run.add_argument("--solver", "-s", metavar="S", help=SOLVER_HELP)
    add_selector_options(run, "every agent")
    run.add_argument(
        "--json",
        action="store_true",
        help="print the summary as one JSON object on stdout (default: a table)",
    )
    run.add_argument(
        "--out",
        metavar="DIR",
        help="also write trajectories.parquet, trajectories.csv (runs of at most "
        f"{CSV_MAX_ROWS:,} agent-samples), summary.json and the figures to DIR "
        "(created; checked before the run)",
    )
    _add_figure_flags(run)
    _add_swarm_flags(run)
    run.set_defaults(func=cmd_run)


def cmd_run(args: argparse.Namespace) -> int:
    plot_options = _figure_options(args)
    sc = with_options(load_or_exit(args.scenario), args.selector_options)
    _swarm_checked(args, sc)
    try:
        check_allotment(sc.n_steps, sc.n_agents, spill_dir=args.spill_dir)
    except ValueError as exc:
        raise UsageError(f"{sc.source}: {exc}") from None
    out = out_dir(args.out) if args.out is not None else None
    sel, formulation, solver = selector(sc, args.formulation, args.solver)
    record, summary = fly_and_summarize(sc, sel, formulation, solver, args)
    status = EXIT_OK
    if out is not None:
        try:
            written = write_outputs(
                record, summary, out, plot_options=plot_options, animate=args.animate
            )
            for path in written:
                log.info("wrote %s", path)
        except OSError as exc:  # the run is done: still print its summary
            log.error("--out %s: writing failed: %s", out, exc.strerror or exc)
            status = EXIT_FAIL
    if args.json:
        print(to_json(summary))
    else:
        print_summary(summary)
    return status


# --------------------------------------------------------------------------- figures


def _add_figure_flags(run: argparse.ArgumentParser) -> None:
    run.add_argument(
        "--format",
        choices=("png", "pdf", "svg"),
        help="file format of the figures (default: png)",
    )
    run.add_argument("--dpi", type=_dpi, help="resolution of PNG figures (default: 150)")
    run.add_argument(
        "--zones",
        type=_zones,
        metavar="WHEN",
        help="vehicles' protected spheres drawn: 'closest' (the closest pair at its "
        "closest approach; default), 'none', or times in s, e.g. '10,20' "
        "(every vehicle at each)",
    )
    run.add_argument(
        "--animate",
        action="store_true",
        help="also write animation.gif, a replay of the run (at most 150 frames)",
    )


def _figure_options(args: argparse.Namespace) -> dict[str, Any]:
    """``write_plots``' keywords from --format, --dpi, --zones; they need --out."""
    given = {
        k: v
        for k, v in (("fmt", args.format), ("dpi", args.dpi), ("zones", args.zones))
        if v is not None
    }
    if args.out is None and (given or args.animate):
        flag = {"fmt": "--format", "dpi": "--dpi", "zones": "--zones"}
        names = [flag[k] for k in given] + (["--animate"] if args.animate else [])
        raise UsageError(f"{', '.join(names)}: figures are written only with --out DIR")
    return given


def _dpi(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 10 <= value <= 2400:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer between 10 and 2400")
    return value


def _zones(text: str) -> Any:
    from vo3d_opt.figures import parse_zones

    try:
        return parse_zones(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


# --------------------------------------------------------------------------- large swarms


def _directory(text: str) -> str:
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not an existing directory")
    return text


def _add_swarm_flags(run: argparse.ArgumentParser) -> None:
    """What a large swarm's run needs: the decisions' threads and neighbours, where the record
    lives (``fly``'s ``spill``, ``spill_dir``)."""
    run.add_argument(
        "--threads",
        type=positive_int,
        metavar="K",
        help="threads of the compiled decisions (select_many; default: every core this process "
        "may use, at most that); the answers do not depend on it. No effect where the agents "
        "decide one at a time (noisy or late sensing, formulations run in Python)",
    )
    run.add_argument(
        "--max-neighbors",
        type=positive_int,
        metavar="K",
        help="each agent avoids only its K nearest vehicles within sensing range (default: "
        "every one in range); noiseless, immediate sensing only",
    )
    run.add_argument(
        "--spill",
        action=argparse.BooleanOptionalAction,
        help="keep the run's record in a temporary file on disk, not in memory (Linux only; "
        "default: when its allotment exceeds 1 GiB; --no-spill: never)",
    )
    run.add_argument(
        "--spill-dir",
        type=_directory,
        metavar="DIR",
        help="an existing, writable directory on disk (not tmpfs) for that file (default: "
        "$TMPDIR); given, a record that cannot spill there is an error, not kept in memory",
    )


def _swarm_checked(args: argparse.Namespace, sc: Scenario) -> None:
    """Refuse before the run what the run would refuse at its start: --threads above the cores,
    --max-neighbors under noisy or late sensing, a spill that cannot happen."""
    if args.threads is not None:
        from vo3d_opt.swarm import thread_count

        try:
            thread_count(args.threads)
        except ValueError as exc:
            raise UsageError(f"--{exc}") from None
    if args.max_neighbors is not None and not sc.sensing.perfect:
        raise UsageError("--max-neighbors: only with noiseless, immediate sensing")
    flag = "--spill-dir" if args.spill_dir else "--spill"
    if args.spill is False:
        if args.spill_dir:
            raise UsageError("--spill-dir: has no effect with --no-spill")
        return
    if not (args.spill or args.spill_dir):
        return
    if not spill_supported():
        raise UsageError(f"{flag}: this platform cannot spill a record (Linux only)")
    where = spill_directory(args.spill_dir)
    if in_memory_fs(where):
        raise UsageError(f"{flag}: {where} is held in memory (tmpfs); choose a directory on disk")
    try:
        with tempfile.TemporaryFile(dir=where):
            pass
    except OSError as exc:
        raise UsageError(f"{flag}: cannot write in {where}: {exc.strerror or exc}") from None
