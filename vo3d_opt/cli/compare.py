"""``vo3d compare SCENARIO --formulations A B --solvers X Y``: every combination flown, one row
per combination with the summary's columns (a JSON list with ``--json``)."""

from __future__ import annotations

import argparse
from typing import Any

from vo3d_opt.selector import DEFAULT_NLP_SOLVER, DEFAULT_QP_SOLVER, FORMULATIONS
from vo3d_opt.sim.metrics import CONTRACT_KEYS
from vo3d_opt.sim.simulator import DEFAULT_FORMULATION

from .common import (
    EXIT_OK,
    SCENARIO_HELP,
    UsageError,
    add_selector_options,
    load_or_exit,
    log,
    selector,
    to_json,
    with_options,
)
from .flight import fly_and_summarize, print_table

TABLE_KEYS = [k for k in CONTRACT_KEYS if k != "scenario"]


def add_compare_parser(sub: Any, common: list[argparse.ArgumentParser]) -> None:
    cmp_ = sub.add_parser(
        "compare",
        parents=common,
        help="run a scenario with several formulations/solvers",
        description="Run a scenario once per formulation x solver (once for "
        "a formulation that uses no solver) and tabulate.",
    )
    cmp_.add_argument("scenario", help=SCENARIO_HELP)
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
    add_selector_options(cmp_, "every run")
    cmp_.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list of summaries on stdout (default: a table)",
    )
    cmp_.set_defaults(func=cmd_compare)


def cmd_compare(args: argparse.Namespace) -> int:
    sc = with_options(load_or_exit(args.scenario), args.selector_options)
    formulations = args.formulations or [sc.formulation or "plane_qp"]
    solvers = args.solvers or [sc.solver]
    built: dict[tuple[str, str], Any] = {}
    failures: dict[tuple[str, str | None], str] = {}
    for f in formulations:
        for s in solvers:
            try:
                sel, formulation, solver = selector(sc, f, s)
            except UsageError as exc:
                failures[(f, s)] = str(exc)
                continue
            if getattr(sel, "solver", solver) is None:  # e.g. sampled: one run, whatever -s
                solver = "none"
            built.setdefault((formulation, solver), sel)
    # A name that fails with every partner is unknown: exit 2. A pair that merely does not go
    # together (e.g. an NLP backend for a QP formulation) is skipped with a note.
    for f in formulations:
        if all((f, s) in failures for s in solvers):
            raise UsageError(failures[(f, solvers[0])])
    for s in solvers:
        if all((f, s) in failures for f in formulations):
            raise UsageError(failures[(formulations[0], s)])
    for msg in failures.values():
        log.warning("skipping %s", msg)
    rows = []
    for (formulation, solver), sel in built.items():
        _, summary = fly_and_summarize(sc, sel, formulation, solver)
        rows.append(summary)
    if args.json:
        print(to_json(rows))
    else:
        print(f"scenario: {sc.name}")
        print_table(rows, TABLE_KEYS)
    return EXIT_OK
