"""The ``vo3d`` command line (contract §3).

* ``vo3d run SCENARIO [--formulation F] [--solver S] [-o KEY=VALUE ...] [--json] [--out DIR]``
  runs one scenario, every agent deciding for itself (the whole swarm in one ``select_many``
  call per step); a table by default, exactly one JSON object on stdout with ``--json``;
  ``--out DIR`` writes ``trajectories.parquet`` (and ``trajectories.csv`` up to
  ``report.CSV_MAX_ROWS`` rows), ``summary.json`` and the figures (``--format png|pdf|svg``,
  ``--dpi``, ``--zones``), and with ``--animate`` ``animation.gif`` (``vo3d_opt.report``). The
  decisions use every core; ``--threads K`` uses fewer.
* ``vo3d compare SCENARIO --formulations A B --solvers X Y [--json]`` runs every combination and
  prints one row per combination with the summary's columns (a JSON list with ``--json``).
* ``vo3d list`` lists the bundled scenarios: name, agents, obstacles, first sentence.
* ``vo3d sweep FAMILY --n N ...`` runs N random encounters on Dask (contract §6;
  ``vo3d_opt.sweep``).
* ``--selector-option KEY=VALUE`` (``-o``, repeatable, the last of a repeated key wins; run,
  compare, sweep): merged over the scenario's ``selector_options`` and checked as they are;
  the summaries carry the scenario's ``selector_options`` so merged. ``--fast`` (same
  commands) stands for ``-o`` of each of ``vo3d_opt.FAST_OPTIONS``, in its place; ``--swarm``
  for those and ``-o horizon=sensing`` (the scenario's ``sensing_horizon``).

SCENARIO is a path or the name of a bundled scenario. Progress and logs go to stderr through
``logging`` (``-q``: warnings and errors only, ``-v``: debugging detail too). Exit status: 0 when
the runs completed (whatever their safety figures), 2 with a one-line message on stderr for an
unreadable or invalid scenario, a bad ``--selector-option``, an unknown formulation or solver, or
an ``--out`` directory that cannot be written (checked before the run), 1 when writing the
outputs fails after the run (the summary is still printed).
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import logging
import os
import re
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from vo3d_opt import __version__
from vo3d_opt.report import CSV_MAX_ROWS, rounded, write_outputs
from vo3d_opt.selector import DEFAULT_NLP_SOLVER, DEFAULT_QP_SOLVER, FAST_OPTIONS, FORMULATIONS
from vo3d_opt.sim.metrics import CONTRACT_KEYS, summarize
from vo3d_opt.sim.scenario import (
    SENSING_HORIZON,
    Scenario,
    ScenarioError,
    bundled_files,
    check_selector_options,
    load_scenario,
    parse_option,
    scenario_variant,
)
from vo3d_opt.sim.simulator import DEFAULT_FORMULATION, Simulator, scenario_selector
from vo3d_opt.sim.spill import in_memory_fs, spill_directory, spill_supported
from vo3d_opt.types import one_line

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2
#: A run of at least this many agents with a formulation or backend that decides in Python
#: (not the compiled plane_qp on exact2d) is warned about: it takes a millisecond or more per
#: agent and step.
SLOW_SWARM = 200

log = logging.getLogger("vo3d_opt.cli")

TABLE_KEYS = [k for k in CONTRACT_KEYS if k != "scenario"]


class _UsageError(Exception):
    """Bad input: printed as one line on stderr, exit status 2."""


class _Formatter(logging.Formatter):
    """Info lines as they are; the others prefixed with their level (errors with ``vo3d:``)."""

    def format(self, record: logging.LogRecord) -> str:
        msg = record.getMessage()
        if record.levelno >= logging.ERROR:
            return f"vo3d: {msg}"
        if record.levelno == logging.INFO:
            return msg
        return f"{record.levelname.lower()}: {msg}"


def configure_logging(verbosity: int = 0) -> None:
    """Send the package's log records to stderr: warnings and errors with ``verbosity`` < 0
    (``-q``), progress too at 0, debugging detail at > 0 (``-v``)."""
    level = logging.WARNING if verbosity < 0 else logging.INFO if verbosity == 0 else logging.DEBUG
    root = logging.getLogger("vo3d_opt")
    for handler in [h for h in root.handlers if getattr(h, "_vo3d_cli", False)]:
        root.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Formatter())
    handler._vo3d_cli = True  # type: ignore[attr-defined]
    root.addHandler(handler)
    root.setLevel(level)
    root.propagate = False


def _json(value: Any) -> str:
    """One line of JSON with floats cut to ``report.JSON_DIGITS`` significant digits."""
    return json.dumps(rounded(value), allow_nan=False)


def _load(arg: str) -> Scenario:
    try:
        return load_scenario(arg)
    except ScenarioError as exc:
        raise _UsageError(str(exc)) from None


def _out_dir(arg: str) -> Path:
    """The ``--out`` directory, created and tried now: a bad path fails before the run."""
    path = Path(arg)
    if path.exists() and not path.is_dir():
        raise _UsageError(f"--out {arg}: exists and is not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        raise _UsageError(f"--out {arg}: cannot write there: {exc.strerror or exc}") from None
    return path


def _selector_option(text: str) -> tuple[str, Any]:
    try:
        return parse_option(text)
    except ScenarioError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _add_selector_option(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--selector-option",
        "-o",
        dest="selector_options",
        type=_selector_option,
        action="append",
        metavar="KEY=VALUE",
        help=f"a selector option for {what}, as the scenario key selector_options takes it "
        "(the keyword arguments of VelocitySelector, README), e.g. closing_guard=false or "
        "margin=0.05; repeatable; overrides the scenario's",
    )
    p.add_argument(
        "--fast",
        dest="selector_options",
        action=_PresetOptions,
        const=list(FAST_OPTIONS.items()),
        nargs=0,
        help="the selector options of vo3d_opt.FAST_OPTIONS ("
        + ", ".join(f"{k}={v}" for k, v in FAST_OPTIONS.items())
        + "): coarser choice, faster decisions, for swarms (README, Swarms; with sampled, its "
        "whole grid); a later -o overrides one",
    )
    p.add_argument(
        "--swarm",
        dest="selector_options",
        action=_PresetOptions,
        const=[*FAST_OPTIONS.items(), ("horizon", SENSING_HORIZON)],
        nargs=0,
        help="the swarm preset: --fast and -o horizon=sensing (the VO ignores meetings further "
        "ahead than the vehicle sensing range over twice the top agent speed, RVO2-3D's time "
        "horizon; README, Swarms); a later -o overrides one",
    )


class _PresetOptions(argparse.Action):
    """``--fast`` / ``--swarm``: their options (``const``: (key, value) pairs) as if given by
    ``-o`` here (so the last of a key still wins)."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        pairs = list(getattr(namespace, self.dest, None) or [])
        setattr(namespace, self.dest, pairs + list(self.const))


def _with_options(sc: Scenario, pairs: list[tuple[str, Any]] | None) -> Scenario:
    """The scenario with ``--selector-option`` merged into its ``selector_options``."""
    if not pairs:
        return sc
    try:
        options = check_selector_options(dict(pairs), "--selector-option")
        log.info("selector options from the command line: %s", options)
        return scenario_variant(sc, selector_options=options)
    except ScenarioError as exc:
        raise _UsageError(str(exc)) from None


def _selector(sc: Scenario, formulation: str | None, solver: str | None) -> tuple[Any, str, str]:
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
def _stdout_to_stderr() -> Iterator[None]:
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


def _run(
    sc: Scenario, sel: Any, formulation: str, solver: str, args: argparse.Namespace | None = None
) -> tuple[Any, dict[str, Any]]:
    """Fly the scenario (``args``: ``vo3d run``'s --threads, --max-neighbors, --spill,
    --spill-dir; None: the defaults); its record and summary."""
    log.info(
        "running %s (%d agents, %d obstacles) with %s / %s",
        sc.name,
        sc.n_agents,
        len(sc.obstacles),
        formulation,
        solver,
    )
    if sc.n_agents >= SLOW_SWARM and not getattr(sel, "compiled", True):
        log.warning(
            "%s / %s decides in Python, a millisecond or more per agent and step: %d agents "
            "will take long (plane_qp on exact2d, the default, is compiled)",
            formulation,
            solver,
            sc.n_agents,
        )
    flags = vars(args) if args is not None else {}
    progress = None if log.isEnabledFor(logging.INFO) else False  # -q: no progress bar either
    sim = Simulator(
        sc,
        sel,
        formulation=formulation,
        solver=solver,
        max_neighbors=flags.get("max_neighbors"),
        threads=flags.get("threads"),
    )
    with _stdout_to_stderr():
        record = sim.run(
            progress=progress, spill=flags.get("spill"), spill_dir=flags.get("spill_dir")
        )
    # what the run added to the simulator's default options: the file's and -o's
    summary = {**summarize(record), "selector_options": dict(sc.selector_options)}
    log.info(
        "done: %d steps, %d/%d arrived, %.2f s wall time",
        summary["steps"],
        summary["reached"],
        summary["agents"],
        record.wall_time,
    )
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
    keys = list(CONTRACT_KEYS) + [
        "status_counts",
        "selector_options",
        "obstacle_pz_intrusions",
        "starts_inside_pz",
        "arrival_time_max",
        "wall_time",
    ]
    width = max(len(k) for k in keys)
    for k in keys:
        if k in summary:
            print(f"{k:<{width}}  {_fmt(summary[k])}")


def _print_table(rows: list[dict[str, Any]], keys: list[str]) -> None:
    cells = [[_fmt(r.get(k)) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[n]) for c in cells)) for n, k in enumerate(keys)]
    print("  ".join(k.ljust(w) for k, w in zip(keys, widths, strict=True)).rstrip())
    for c in cells:
        print("  ".join(v.ljust(w) for v, w in zip(c, widths, strict=True)).rstrip())


def _figure_options(args: argparse.Namespace) -> dict[str, Any]:
    """``write_plots``' keywords from --format, --dpi, --zones; they need --out."""
    given = {
        k: v
        for k, v in (("fmt", args.format), ("dpi", args.dpi), ("zones", args.zones))
        if v is not None
    }
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
    sc = _with_options(_load(args.scenario), args.selector_options)
    _swarm_checked(args, sc)
    out = _out_dir(args.out) if args.out else None
    sel, formulation, solver = _selector(sc, args.formulation, args.solver)
    record, summary = _run(sc, sel, formulation, solver, args)
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
        print(_json(summary))
    else:
        _print_summary(summary)
    return status


def cmd_compare(args: argparse.Namespace) -> int:
    sc = _with_options(_load(args.scenario), args.selector_options)
    formulations = args.formulations or [sc.formulation or "plane_qp"]
    solvers = args.solvers or [sc.solver]
    built: dict[tuple[str, str], Any] = {}
    failures: dict[tuple[str, str | None], str] = {}
    for f in formulations:
        for s in solvers:
            try:
                sel, formulation, solver = _selector(sc, f, s)
            except _UsageError as exc:
                failures[(f, s)] = str(exc)
                continue
            if getattr(sel, "solver", solver) is None:  # e.g. sampled: one run, whatever -s
                solver = "none"
            built.setdefault((formulation, solver), sel)
    # A name that fails with every partner is unknown: exit 2. A pair that merely does not go
    # together (e.g. an NLP backend for a QP formulation) is skipped with a note.
    for f in formulations:
        if all((f, s) in failures for s in solvers):
            raise _UsageError(failures[(f, solvers[0])])
    for s in solvers:
        if all((f, s) in failures for f in formulations):
            raise _UsageError(failures[(formulations[0], s)])
    for msg in failures.values():
        log.warning("skipping %s", msg)
    rows = []
    for (formulation, solver), sel in built.items():
        _, summary = _run(sc, sel, formulation, solver)
        rows.append(summary)
    if args.json:
        print(_json(rows))
    else:
        print(f"scenario: {sc.name}")
        _print_table(rows, TABLE_KEYS)
    return EXIT_OK


def _first_sentence(text: str) -> str:
    """Up to the first full stop followed by a capital ("Figs. 13-14" does not end it)."""
    text = one_line(text)
    match = re.search(r"\.\s+(?=[A-Z])", text)
    return text[: match.start() + 1] if match else text


def cmd_list(args: argparse.Namespace) -> int:
    rows, bad = [], 0
    for path in bundled_files():
        try:
            sc = load_scenario(path)
        except ScenarioError as exc:
            log.error("%s", exc)
            bad += 1
            continue
        obstacles = str(len(sc.obstacles)) + (f"+{len(sc.spheres)}s" if sc.spheres else "")
        rows.append((sc.name, str(sc.n_agents), obstacles, _first_sentence(sc.description)))
    if args.json:
        print(
            _json(
                [
                    dict(zip(("name", "agents", "obstacles", "description"), r, strict=True))
                    for r in rows
                ]
            )
        )
        return EXIT_FAIL if bad else EXIT_OK
    if rows:
        w = [max(len(r[n]) for r in rows + [("name", "agents", "obstacles", "")]) for n in range(3)]
        print(f"{'name':<{w[0]}}  {'agents':>{w[1]}}  {'obstacles':>{w[2]}}  description")
        for r in rows:
            print(f"{r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:>{w[2]}}  {r[3]}")
    return EXIT_FAIL if bad else EXIT_OK


def cmd_sweep(args: argparse.Namespace) -> int:
    from vo3d_opt.sweep import command  # Dask and pandas load only for sweeps

    if args.out and not args.list:
        _out_dir(args.out)  # a bad --out fails before the sweep, not after it
    try:
        return command.main(args, protect_stdout=_stdout_to_stderr)
    except command.SweepError as exc:
        raise _UsageError(str(exc)) from None


def _int_at_least(least: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer >= ``least``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"must be >= {least}, got {value}")
        return value

    return parse


_non_negative_int, _positive_int = _int_at_least(0), _int_at_least(1)


def _cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _add_sweep(sub: Any, common: list[_Parser]) -> None:
    sw = sub.add_parser(
        "sweep",
        parents=common,
        help="run N random encounters of a family on Dask (contract §6)",
        description="Run N random encounters of a family on a Dask cluster and report rates with "
        "95% Clopper-Pearson bounds. Exit status 0 when every encounter ran, 1 when "
        "some raised or lost their worker (listed in the summary) or writing --out failed, "
        "2 for bad options.",
    )
    sw.add_argument("family", nargs="?", help="encounter family (vo3d sweep --list names them)")
    sw.add_argument("--list", action="store_true", help="list the families, one line each")
    sw.add_argument("--n", type=_non_negative_int, metavar="N", help="number of encounters (>= 1)")
    sw.add_argument(
        "--seed",
        type=_non_negative_int,
        default=0,
        metavar="S",
        help="sweep seed (>= 0, default 0); encounter i is drawn from (S, i)",
    )
    where = sw.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=_non_negative_int,
        metavar="K",
        default=_cpus(),
        help="local Dask worker processes, one thread each (default: the CPUs)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="use the existing Dask scheduler at ADDRESS (tcp://host:8786)",
    )
    sw.add_argument(
        "--method",
        choices=("vo3d", "rvo2"),
        default="vo3d",
        help="vo3d (default) or rvo2: RVO2-3D, obstacle-free families only",
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
    _add_selector_option(sw, "every encounter (--method vo3d)")
    sw.add_argument(
        "--out",
        metavar="DIR",
        help="also write encounters.parquet, summary.json, min_distance.png and "
        "failures/*.yaml (replayable by vo3d run) to DIR (created; checked before the sweep)",
    )
    sw.add_argument(
        "--json",
        action="store_true",
        help="print the summary as one JSON object on stdout (default: a table)",
    )
    sw.add_argument(
        "--in-flight",
        type=_non_negative_int,
        metavar="M",
        help="encounters submitted at once (default 4 per worker, at least 8)",
    )
    sw.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    sw.set_defaults(func=cmd_sweep)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # one line on stderr, exit 2 (argparse's status)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {one_line(message)}\n")


_SCENARIO_HELP = "a scenario YAML file, or the name of a bundled scenario (see `vo3d list`)"
_SOLVER_HELP = (
    f"osqp | clarabel | daqp | cvxpy[:SOLVER] | qpsolvers:NAME | casadi[:PLUGIN]; "
    f"default: the scenario's `solver`, else {DEFAULT_QP_SOLVER} for the QP "
    f"formulations and {DEFAULT_NLP_SOLVER} for nlp (sampled uses none)"
)


def _common() -> _Parser:
    """The options every subcommand takes (-v / -q)."""
    p = _Parser(add_help=False)
    noise = p.add_mutually_exclusive_group()
    noise.add_argument(
        "-v",
        "--verbose",
        dest="verbosity",
        action="store_const",
        const=1,
        default=0,
        help="log debugging detail on stderr too",
    )
    noise.add_argument(
        "-q",
        "--quiet",
        dest="verbosity",
        action="store_const",
        const=-1,
        help="log only warnings and errors on stderr (no progress)",
    )
    return p


def _directory(text: str) -> str:
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not an existing directory")
    return text


def _add_swarm_flags(run: argparse.ArgumentParser) -> None:
    """What a large swarm's run needs: the decisions' threads and neighbours, where the record
    lives (``fly``'s ``spill``, ``spill_dir``)."""
    run.add_argument(
        "--threads",
        type=_positive_int,
        metavar="K",
        help="threads of the compiled decisions (select_many; default: every core this process "
        "may use, at most that); the answers do not depend on it. No effect where the agents "
        "decide one at a time (noisy or late sensing, formulations run in Python)",
    )
    run.add_argument(
        "--max-neighbors",
        type=_positive_int,
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
            raise _UsageError(f"--{exc}") from None
    if args.max_neighbors is not None and not sc.sensing.perfect:
        raise _UsageError("--max-neighbors: only with noiseless, immediate sensing")
    flag = "--spill-dir" if args.spill_dir else "--spill"
    if args.spill is False:
        if args.spill_dir:
            raise _UsageError("--spill-dir: has no effect with --no-spill")
        return
    if not (args.spill or args.spill_dir):
        return
    if not spill_supported():
        raise _UsageError(f"{flag}: this platform cannot spill a record (Linux only)")
    where = spill_directory(args.spill_dir)
    if in_memory_fs(where):
        raise _UsageError(f"{flag}: {where} is held in memory (tmpfs); choose a directory on disk")
    try:
        with tempfile.TemporaryFile(dir=where):
            pass
    except OSError as exc:
        raise _UsageError(f"{flag}: cannot write in {where}: {exc.strerror or exc}") from None


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vo3d", description="Improved 3D velocity obstacle: multi-UAV simulations.")
    p.add_argument(
        "--version",
        action="version",
        version=f"vo3d {__version__}",
        help="print the version and exit",
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    common = [_common()]

    run = sub.add_parser(
        "run",
        parents=common,
        help="run one scenario",
        description="Run one scenario, every agent deciding for itself.",
    )
    run.add_argument("scenario", help=_SCENARIO_HELP)
    run.add_argument(
        "--formulation",
        "-f",
        metavar="F",
        help=f"{' | '.join(FORMULATIONS)}; default: the scenario's `formulation`, "
        f"else {DEFAULT_FORMULATION}",
    )
    run.add_argument("--solver", "-s", metavar="S", help=_SOLVER_HELP)
    _add_selector_option(run, "every agent")
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
    _add_swarm_flags(run)
    run.set_defaults(func=cmd_run)

    cmp_ = sub.add_parser(
        "compare",
        parents=common,
        help="run a scenario with several formulations/solvers",
        description="Run a scenario once per formulation x solver (once for "
        "a formulation that uses no solver) and tabulate.",
    )
    cmp_.add_argument("scenario", help=_SCENARIO_HELP)
    cmp_.add_argument(
        "--formulations",
        nargs="+",
        metavar="F",
        help=f"some of {', '.join(FORMULATIONS)}; default: the scenario's "
        f"`formulation`, else {DEFAULT_FORMULATION}",
    )
    cmp_.add_argument(
        "--solvers",
        nargs="+",
        metavar="S",
        help="solver names as for `vo3d run --solver`; default: the scenario's "
        f"`solver`, else {DEFAULT_QP_SOLVER} (QP) / {DEFAULT_NLP_SOLVER} (nlp)",
    )
    _add_selector_option(cmp_, "every run")
    cmp_.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list of summaries on stdout (default: a table)",
    )
    cmp_.set_defaults(func=cmd_compare)

    lst = sub.add_parser(
        "list",
        parents=common,
        help="list the bundled scenarios",
        description="List the bundled scenarios: name, agents, obstacles, "
        "first sentence of the description.",
    )
    lst.add_argument(
        "--json", action="store_true", help="print a JSON list on stdout (default: a table)"
    )
    lst.set_defaults(func=cmd_list)
    _add_sweep(sub, common)

    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``vo3d``; returns (and, as a script, exits with) the status."""
    args = build_parser().parse_args(argv)
    configure_logging(args.verbosity)
    try:
        return int(args.func(args))
    except _UsageError as exc:
        log.error("%s", one_line(exc))
        return EXIT_USAGE
    except KeyboardInterrupt:
        log.error("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
