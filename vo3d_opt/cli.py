"""The ``vo3d`` command line (contract §3).

* ``vo3d run SCENARIO [--formulation F] [--solver S] [--json] [--out DIR]`` runs one scenario,
  every agent deciding for itself; a table by default, exactly one JSON object on stdout with
  ``--json``; ``--out DIR`` writes ``trajectories.csv``, ``summary.json`` and the figures
  (``--format png|pdf|svg``, ``--dpi``, ``--zones``), and with ``--animate`` ``animation.gif``.
* ``vo3d compare SCENARIO --formulations A B --solvers X Y [--json]`` runs every combination and
  prints one row per combination with the summary's columns (a JSON list with ``--json``).
* ``vo3d list`` lists the bundled scenarios: name, agents, obstacles, first sentence.

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


def write_outputs(record: Any, summary: dict[str, Any], out: Path, *,
                  plot_options: dict[str, Any] | None = None, animate: bool = False) -> list[Path]:
    """trajectories.csv, summary.json, the figures (``plot_options``: ``write_plots``'
    keywords) and with ``animate`` animation.gif of a run in ``out``; the paths."""
    from vo3d_opt.plots import skipped_plots, write_plots  # matplotlib only when asked for

    out.mkdir(parents=True, exist_ok=True)
    written = [write_csv(record, out / "trajectories.csv")]
    path = out / "summary.json"
    path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    written.append(path)
    written += write_plots(record, out, **(plot_options or {}))
    for name, why in skipped_plots(record).items():
        _log(f"not drawn: {name} ({why})")
    if animate:
        from vo3d_opt.animation import write_animation

        written.append(write_animation(record, out / "animation.gif"))
    return written


def _figure_options(args: argparse.Namespace) -> dict[str, Any]:
    """``write_plots``' keywords from --format, --dpi, --zones; they need --out."""
    given = {k: v for k, v in (("fmt", args.format), ("dpi", args.dpi), ("zones", args.zones))
             if v is not None}
    if not args.out and (given or args.animate):
        flag = {"fmt": "--format", "dpi": "--dpi", "zones": "--zones"}
        names = [flag[k] for k in given] + (["--animate"] if args.animate else [])
        raise _UsageError(f"{', '.join(names)}: figures are written only with --out DIR")
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
    from vo3d_opt.plots import parse_zones

    try:
        return parse_zones(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def cmd_run(args: argparse.Namespace) -> int:
    plot_options = _figure_options(args)
    sc = _load(args.scenario)
    sel, formulation, solver = _selector(sc, args.formulation, args.solver)
    record, summary = _run(sc, sel, formulation, solver)
    if args.out:
        for path in write_outputs(record, summary, Path(args.out), plot_options=plot_options,
                                  animate=args.animate):
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
    run.add_argument("--out", metavar="DIR",
                     help="write trajectories.csv, summary.json and the figures there")
    run.add_argument("--format", choices=("png", "pdf", "svg"),
                     help="file format of the figures (default: png)")
    run.add_argument("--dpi", type=_dpi, help="resolution of PNG figures (default: 150)")
    run.add_argument("--zones", type=_zones, metavar="WHEN",
                     help="vehicles' protected spheres drawn: 'closest' (the closest pair at its "
                          "closest approach; default), 'none', or times in s, e.g. '10,20' "
                          "(every vehicle at each)")
    run.add_argument("--animate", action="store_true",
                     help="also write animation.gif, a replay of the run (at most 150 frames)")
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
