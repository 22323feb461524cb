"""``vo3d list``: the bundled scenarios, one line each (name, agents, obstacles, the first
sentence of the description)."""

from __future__ import annotations

import argparse
import re
from typing import Any

from vo3d_opt.sim.scenario import ScenarioError, bundled_files, load_scenario
from vo3d_opt.types import one_line

from .common import EXIT_FAIL, EXIT_OK, log, to_json


def add_list_parser(sub: Any, common: list[argparse.ArgumentParser]) -> None:
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


def first_sentence(text: str) -> str:
    """Up to the first full stop followed by a capital ("Figs. 13-14" does not end it)."""
    text = one_line(text)
    match = re.search(r"\.\s+(?=[A-Z])", text)
    return text[: match.start() + 1] if match else text


def cmd_list(args: argparse.Namespace) -> int:
    rows, bad = [], 0
    for path in bundled_files():
        try:
            sc = load_scenario(path, warn=False)  # a listing, not a run: no warnings
        except ScenarioError as exc:
            log.error("%s", exc)
            bad += 1
            continue
        obstacles = str(len(sc.obstacles)) + (f"+{len(sc.spheres)}s" if sc.spheres else "")
        rows.append((sc.name, str(sc.n_agents), obstacles, first_sentence(sc.description)))
    if args.json:
        keys = ("name", "agents", "obstacles", "description")
        print(to_json([dict(zip(keys, r, strict=True)) for r in rows]))
        return EXIT_FAIL if bad else EXIT_OK
    if rows:
        w = [max(len(r[n]) for r in rows + [("name", "agents", "obstacles", "")]) for n in range(3)]
        print(f"{'name':<{w[0]}}  {'agents':>{w[1]}}  {'obstacles':>{w[2]}}  description")
        for r in rows:
            print(f"{r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:>{w[2]}}  {r[3]}")
    return EXIT_FAIL if bad else EXIT_OK
