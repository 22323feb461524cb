"""The ``vo3d`` command line (contract §3).

* ``vo3d run SCENARIO [--formulation F] [--solver S] [--json] [--out DIR]`` runs one scenario,
  every agent deciding for itself; a table by default, exactly one JSON object on stdout with
  ``--json``; ``--out DIR`` writes ``trajectories.csv``, ``summary.json`` and the PNG figures.
* ``vo3d compare SCENARIO --formulations A B --solvers X Y [--json]`` runs every combination and
  prints one row per combination with the summary's columns (a JSON list with ``--json``).
* ``vo3d list`` lists the bundled scenarios: name, agents, obstacles, first sentence.
* ``vo3d sweep FAMILY --n N ...`` runs N random encounters on Dask (contract §6; ``vo3d_opt.sweep``).

SCENARIO is a path or the name of a bundled scenario. Progress and logs go to stderr. Exit
status: 0 when the runs completed (whatever their safety figures), 2 with a one-line message on
stderr for an unreadable or invalid scenario or an unknown formulation or solver.
"""
from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import os
import re
import sys
from pathlib import Path
from typing import Any, Sequence

from vo3d_opt.sim.metrics import CONTRACT_KEYS, summarize
from vo3d_opt.sim.scenario import Scenario, ScenarioError, bundled_files, load_scenario, resolve
from vo3d_opt.sim.simulator import Simulator, scenario_selector, write_csv

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2

TABLE_KEYS = [k for k in CONTRACT_KEYS if k != "scenario"]


class _UsageError(Exception):
    """Bad input: printed as one line on stderr, exit status 2."""


def _one_line(text: Any) -> str:
    return " ".join(str(text).split())


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _load(arg: str) -> Scenario:
    try:
        return load_scenario(resolve(arg))
    except ScenarioError as exc:
        raise _UsageError(str(exc)) from None


def _selector(sc: Scenario, formulation: str | None, solver: str | None):
    try:
        return scenario_selector(sc, formulation, solver)
    except (ValueError, TypeError) as exc:
        f, s = formulation or sc.formulation, solver or sc.solver
        what = f"formulation {f or 'default'!r}, solver {s or 'default'!r}"
        raise _UsageError(f"{what}: {exc}") from None


def _c_flush() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # pragma: no cover - no libc (Windows)
        pass


@contextlib.contextmanager
def _stdout_to_stderr():
    """Send file descriptor 1 to stderr while solvers run: some native solvers print on the
    C-level stdout, which would corrupt the one JSON object stdout must carry."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):  # no real fd 1: nothing to protect
        yield
        return
    try:
        os.dup2(2, 1)
        yield
    finally:
        _c_flush()
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _run(sc: Scenario, sel: Any, formulation: str, solver: str) -> tuple[Any, dict[str, Any]]:
    for warning in sc.start_warnings():
        _log(f"warning: {warning}")
    _log(f"running {sc.name} ({sc.n_agents} agents, {len(sc.obstacles)} obstacles) with "
         f"{formulation} / {solver}")
    with _stdout_to_stderr():
        record = Simulator(sc, sel, formulation=formulation, solver=solver).run()
    summary = summarize(record)
    _log(f"done: {summary['steps']} steps, {summary['reached']}/{summary['agents']} arrived, "
         f"{record.wall_time:.2f} s wall time")
    return record, summary


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}" if abs(value) < 1e4 else f"{value:.0f}"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {v}" for k, v in value.items()) or "-"
    return str(value)


def _print_summary(summary: dict[str, Any]) -> None:
    keys = list(CONTRACT_KEYS) + ["status_counts", "obstacle_pz_intrusions", "starts_inside_pz",
                                  "arrival_time_max", "wall_time"]
    width = max(len(k) for k in keys)
    for k in keys:
        if k in summary:
            print(f"{k:<{width}}  {_fmt(summary[k])}")


def _print_table(rows: list[dict[str, Any]], keys: list[str]) -> None:
    cells = [[_fmt(r.get(k)) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[n]) for c in cells)) for n, k in enumerate(keys)]
    print("  ".join(k.ljust(w) for k, w in zip(keys, widths)).rstrip())
    for c in cells:
        print("  ".join(v.ljust(w) for v, w in zip(c, widths)).rstrip())


def write_outputs(record: Any, summary: dict[str, Any], out: Path) -> list[Path]:
    """trajectories.csv, summary.json and the PNG plots of a run in ``out``; the paths."""
    from vo3d_opt.plots import write_plots  # matplotlib only when asked for

    out.mkdir(parents=True, exist_ok=True)
    written = [write_csv(record, out / "trajectories.csv")]
    path = out / "summary.json"
    path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    written.append(path)
    written += write_plots(record, out)
    return written


def cmd_run(args: argparse.Namespace) -> int:
    sc = _load(args.scenario)
    sel, formulation, solver = _selector(sc, args.formulation, args.solver)
    record, summary = _run(sc, sel, formulation, solver)
    if args.out:
        for path in write_outputs(record, summary, Path(args.out)):
            _log(f"wrote {path}")
    if args.json:
        print(json.dumps(summary, allow_nan=False))
    else:
        _print_summary(summary)
    return EXIT_OK


def cmd_compare(args: argparse.Namespace) -> int:
    sc = _load(args.scenario)
    formulations = args.formulations or [sc.formulation or "plane_qp"]
    solvers = args.solvers or [sc.solver]
    built: list[tuple[Any, str, str]] = []
    failures: dict[tuple[str, str | None], str] = {}
    for f in formulations:
        for s in solvers:
            try:
                built.append(_selector(sc, f, s))
            except _UsageError as exc:
                failures[(f, s)] = str(exc)
    # A name that fails with every partner is unknown: exit 2. A pair that merely does not go
    # together (e.g. an NLP backend for a QP formulation) is skipped with a note.
    for f in formulations:
        if all((f, s) in failures for s in solvers):
            raise _UsageError(failures[(f, solvers[0])])
    for s in solvers:
        if all((f, s) in failures for f in formulations):
            raise _UsageError(failures[(formulations[0], s)])
    for msg in failures.values():
        _log(f"skipping {msg}")
    rows = []
    for sel, formulation, solver in built:
        _, summary = _run(sc, sel, formulation, solver)
        rows.append(summary)
    if args.json:
        print(json.dumps(rows, allow_nan=False))
    else:
        print(f"scenario: {sc.name}")
        _print_table(rows, TABLE_KEYS)
    return EXIT_OK


def _first_sentence(text: str) -> str:
    """Up to the first full stop followed by a capital ("Figs. 13-14" does not end it)."""
    text = _one_line(text)
    match = re.search(r"\.\s+(?=[A-Z])", text)
    return text[: match.start() + 1] if match else text


def cmd_list(args: argparse.Namespace) -> int:
    rows, bad = [], 0
    for path in bundled_files():
        try:
            sc = load_scenario(path)
        except ScenarioError as exc:
            _log(str(exc))
            bad += 1
            continue
        obstacles = str(len(sc.obstacles)) + (f"+{len(sc.spheres)}s" if sc.spheres else "")
        rows.append((sc.name, str(sc.n_agents), obstacles, _first_sentence(sc.description)))
    if args.json:
        print(json.dumps([dict(zip(("name", "agents", "obstacles", "description"), r))
                          for r in rows]))
        return EXIT_FAIL if bad else EXIT_OK
    if rows:
        w = [max(len(r[n]) for r in rows + [("name", "agents", "obstacles", "")]) for n in range(3)]
        print(f"{'name':<{w[0]}}  {'agents':>{w[1]}}  {'obstacles':>{w[2]}}  description")
        for r in rows:
            print(f"{r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:>{w[2]}}  {r[3]}")
    return EXIT_FAIL if bad else EXIT_OK


def cmd_sweep(args: argparse.Namespace) -> int:
    from vo3d_opt.sweep import command  # Dask and pandas load only for sweeps

    try:
        return command.main(args, log=_log, protect_stdout=_stdout_to_stderr)
    except command.SweepError as exc:
        raise _UsageError(str(exc)) from None


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _add_sweep(sub: Any) -> None:
    sw = sub.add_parser(
        "sweep", help="run N random encounters of a family on Dask (contract §6)",
        description="Run N random encounters of a family on a Dask cluster and report rates with "
                    "95% Clopper-Pearson bounds. Exit status 0 when every encounter ran, 1 when "
                    "some raised or lost their worker (listed in the summary), 2 for bad options.")
    sw.add_argument("family", nargs="?", help="encounter family (vo3d sweep --list names them)")
    sw.add_argument("--list", action="store_true", help="list the families, one line each")
    sw.add_argument("--n", type=_positive_int, metavar="N", help="number of encounters (>= 1)")
    sw.add_argument("--seed", type=_positive_int, default=0, metavar="S",
                    help="sweep seed (>= 0, default 0); encounter i is drawn from (S, i)")
    where = sw.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive_int, metavar="K",
                       default=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                       else (os.cpu_count() or 1),
                       help="local Dask worker processes, one thread each (default: the CPUs)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use the existing Dask scheduler at ADDRESS (tcp://host:8786)")
    sw.add_argument("--method", choices=("vo3d", "rvo2"), default="vo3d",
                    help="vo3d (default) or rvo2: RVO2-3D, obstacle-free families only")
    sw.add_argument("--formulation", "-f", help="sampled | plane_qp (default) | cone_qp | nlp")
    sw.add_argument("--solver", "-s", help="osqp, clarabel, cvxpy[:S], qpsolvers:<name>, casadi")
    sw.add_argument("--out", metavar="DIR", help="write encounters.parquet, summary.json, "
                    "min_distance.png and failures/*.yaml (replayable by vo3d run)")
    sw.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    sw.add_argument("--in-flight", type=_positive_int, metavar="M",
                    help="encounters submitted at once (default 4 per worker, at least 8)")
    sw.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    sw.set_defaults(func=cmd_sweep)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line on stderr, exit 2 (argparse's status)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {_one_line(message)}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vo3d", description="Improved 3D velocity obstacle: multi-UAV simulations.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="run one scenario")
    run.add_argument("scenario", help="scenario YAML file or bundled scenario name")
    run.add_argument("--formulation", "-f", help="sampled | plane_qp (default) | cone_qp | nlp")
    run.add_argument("--solver", "-s", help="osqp, clarabel, cvxpy[:S], qpsolvers:<name>, casadi")
    run.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    run.add_argument("--out", metavar="DIR", help="write trajectories.csv, summary.json, PNGs")
    run.set_defaults(func=cmd_run)

    cmp_ = sub.add_parser("compare", help="run a scenario with several formulations/solvers")
    cmp_.add_argument("scenario", help="scenario YAML file or bundled scenario name")
    cmp_.add_argument("--formulations", nargs="+", metavar="F")
    cmp_.add_argument("--solvers", nargs="+", metavar="S")
    cmp_.add_argument("--json", action="store_true", help="print a JSON list on stdout")
    cmp_.set_defaults(func=cmd_compare)

    lst = sub.add_parser("list", help="list the bundled scenarios")
    lst.add_argument("--json", action="store_true", help="print a JSON list on stdout")
    lst.set_defaults(func=cmd_list)
    _add_sweep(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``vo3d``; returns (and, as a script, exits with) the status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except _UsageError as exc:
        print(f"vo3d: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("vo3d: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
