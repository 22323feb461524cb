"""The ``vo3d`` parser and its entry point, once the ``[sim]`` extra is known to be there
(``vo3d_opt.cli.main`` checks first)."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from vo3d_opt import __version__
from vo3d_opt.console import configure_logging
from vo3d_opt.extras import MissingExtra
from vo3d_opt.link.command import add_parsers as add_link_parsers
from vo3d_opt.types import one_line

from .common import (
    EXIT_FAIL,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    Parser,
    UsageError,
    common_parser,
    log,
)
from .compare import add_compare_parser
from .listing import add_list_parser
from .run import add_run_parser
from .schema import add_schema_parser
from .sweep import add_sweep_parser

#: Each subcommand's parser, in the order ``vo3d --help`` lists them.
SUBCOMMANDS = (
    add_run_parser,
    add_compare_parser,
    add_list_parser,
    add_sweep_parser,
    add_schema_parser,
    add_link_parsers,
)


def build_vo3d_parser() -> argparse.ArgumentParser:
    p = Parser(prog="vo3d", description="Improved 3D velocity obstacle: multi-UAV simulations.")
    p.add_argument(
        "--version",
        action="version",
        version=f"vo3d {__version__}",
        help="print the version and exit",
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    common: list[argparse.ArgumentParser] = [common_parser()]
    for add_parser in SUBCOMMANDS:
        add_parser(sub, common)
    return p


def run_command_line(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``vo3d``; returns (and, as a script, exits with) the status."""
    args = build_vo3d_parser().parse_args(argv)
    configure_logging(args.verbosity)
    try:
        return int(args.func(args))
    except (UsageError, MissingExtra) as exc:
        log.error("%s", one_line(exc))
        return EXIT_USAGE
    except KeyboardInterrupt:
        log.error("interrupted")
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # stdout's reader went away (| head): no traceback, no more output
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAIL
