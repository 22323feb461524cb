"""The ``vo3d`` command line: one module per subcommand.

* ``vo3d run SCENARIO`` (:mod:`.run`), ``vo3d compare`` (:mod:`.compare`), ``vo3d list``
  (:mod:`.listing`), ``vo3d sweep FAMILY --n N`` (:mod:`.sweep`), ``vo3d link`` and
  ``vo3d sitl`` (``vo3d_opt.link.command``).
* ``--preset NAME`` (``--fast``, ``--swarm`` its aliases) and ``-o KEY=VALUE`` (run, compare,
  sweep): the selector's configuration, merged over the scenario's ``selector_options`` in the
  order given (the last of a key wins) and checked as the file's are.

SCENARIO is a path or the name of a bundled scenario. Progress and logs go to stderr through
``logging`` (``-q``: warnings and errors only, ``-v``: debugging detail too). Exit status: 0
when the runs completed (whatever their safety figures), 2 with a one-line message on stderr for
bad input (an unreadable or invalid scenario, a bad option, an unknown formulation or solver,
an ``--out`` directory that cannot be written: checked before the run), 1 when writing the
outputs fails after the run (the summary is still printed), 130 when interrupted.

The command line needs the ``[sim]`` extra (YAML scenarios, progress bars, figures, Parquet):
without it every ``vo3d`` command prints one line naming it and exits 2, and a feature of
another extra missing (``vo3d sweep``: ``[sweep]``, ``--solver osqp``: ``[qp]``, ...) does the
same. The parser is in :mod:`.app`, imported only once the extra is there.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from vo3d_opt.extras import MissingExtra, check

#: Exit status for bad input and for a missing extra (argparse's own).
EXIT_USAGE = 2


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``vo3d``; returns (and, as a script, exits with) the status."""
    try:
        check("sim", "the vo3d command line")
        from tqdm import tqdm

        from .app import run_command_line
    except MissingExtra as exc:
        print(f"vo3d: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    # no tqdm monitor thread: a Ctrl-C that lands in its exit handler prints a traceback
    tqdm.monitor_interval = 0
    return run_command_line(argv)


def build_parser() -> argparse.ArgumentParser:
    """The whole ``vo3d`` parser (needs the ``[sim]`` extra)."""
    from .app import build_vo3d_parser

    return build_vo3d_parser()
