"""The ``vo3d`` command line: one module per subcommand.

* ``vo3d run SCENARIO`` (:mod:`.run`), ``vo3d compare`` (:mod:`.compare`), ``vo3d list``
  (:mod:`.listing`), ``vo3d sweep FAMILY --n N`` (:mod:`.sweep`), ``vo3d schema``
  (:mod:`.schema`), ``vo3d link`` and ``vo3d sitl`` (``vo3d_opt.link.command``).
* ``--preset NAME`` (``--fast``, ``--swarm`` its aliases) and ``-o KEY=VALUE`` (run, compare,
  sweep): the selector's configuration, merged over the scenario's ``selector_options`` in the
  order given (the last of a key wins) and checked as the file's are.

SCENARIO is a path or the name of a bundled scenario. Progress and logs go to stderr through
``logging`` (``-q``: warnings and errors only, ``-v``: debugging detail too). Exit status: 0
when the runs completed (whatever their safety figures), 2 with a one-line message on stderr for
bad input (an unreadable or invalid scenario, a bad option, an unknown formulation or solver,
an ``--out`` directory that cannot be written: checked before the run), 1 when writing the
outputs fails after the run (the summary is still printed), 130 when interrupted.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from vo3d_opt import __version__
from vo3d_opt.console import configure_logging
from vo3d_opt.link.command import add_parsers as add_link_parsers
from vo3d_opt.types import one_line

from .common import EXIT_FAIL, EXIT_USAGE, Parser, UsageError, common_parser, log
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


def build_parser() -> argparse.ArgumentParser:
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``vo3d``; returns (and, as a script, exits with) the status."""
    args = build_parser().parse_args(argv)
    configure_logging(args.verbosity)
    try:
        return int(args.func(args))
    except UsageError as exc:
        log.error("%s", one_line(exc))
        return EXIT_USAGE
    except KeyboardInterrupt:
        log.error("interrupted")
        return 130
    except BrokenPipeError:  # stdout's reader went away (| head): no traceback, no more output
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAIL


if __name__ == "__main__":
    sys.exit(main())
