"""What every ``vo3d`` subcommand shares: the parser class (one-line errors, exit 2), logging
on stderr, the ``-v``/``-q`` and selector-option flags, loading a scenario, checking ``--out``,
printing JSON, and keeping native solvers' prints off stdout."""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import logging
import os
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from vo3d_opt.config import PRESETS, describe
from vo3d_opt.extras import MissingExtra
from vo3d_opt.report import rounded
from vo3d_opt.selector import DEFAULT_SOLVERS
from vo3d_opt.sim.scenario import (
    Scenario,
    ScenarioError,
    check_selector_options,
    load_scenario,
    parse_option,
    scenario_variant,
)
from vo3d_opt.sim.simulator import DEFAULT_FORMULATION, scenario_selector
from vo3d_opt.types import one_line

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report a Ctrl-C

log = logging.getLogger("vo3d_opt.cli")

SCENARIO_HELP = "a scenario YAML file, or the name of a bundled scenario (see `vo3d list`)"


class UsageError(Exception):
    """Bad input: printed as one line on stderr, exit status 2."""


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # one line on stderr, exit 2 (argparse's status)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {one_line(message)}\n")


def common_parser() -> Parser:
    """The options every subcommand takes (-v / -q)."""
    p = Parser(add_help=False)
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


def to_json(value: Any) -> str:
    """One line of JSON with floats cut to ``report.JSON_DIGITS`` significant digits."""
    return json.dumps(rounded(value), allow_nan=False)


def load_or_exit(arg: str) -> Scenario:
    """The scenario ``arg`` names; an unreadable or invalid one is a ``UsageError``."""
    try:
        return load_scenario(arg)
    except ScenarioError as exc:
        raise UsageError(str(exc)) from None


def out_dir(arg: str) -> Path:
    """The ``--out`` directory, created and tried now: a bad path fails before the run."""
    if not arg.strip():
        raise UsageError("--out: an empty path; give a directory")
    path = Path(arg)
    if path.exists() and not path.is_dir():
        raise UsageError(f"--out {arg}: exists and is not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        raise UsageError(f"--out {arg}: cannot write there: {exc.strerror or exc}") from None
    return path


def int_at_least(least: int) -> Callable[[str], int]:
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


non_negative_int, positive_int = int_at_least(0), int_at_least(1)

# --------------------------------------------------------------------------- selector options


def _selector_option(text: str) -> tuple[str, Any]:
    try:
        return parse_option(text)
    except ScenarioError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


class _Preset(argparse.Action):
    """``--preset NAME`` (and its aliases ``--fast``, ``--swarm``, whose ``const`` is the
    name): ``preset=NAME`` among the ``-o`` pairs, in its place (the last of a key wins)."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        name = self.const if self.const is not None else values
        pairs = list(getattr(namespace, self.dest, None) or [])
        setattr(namespace, self.dest, [*pairs, ("preset", name)])


def add_selector_options(
    p: argparse.ArgumentParser, what: str, default: str = "the scenario's, else safe"
) -> None:
    """``--preset``, its aliases ``--fast`` and ``--swarm``, and ``-o KEY=VALUE``; ``default``:
    which preset applies without them, as the help says it."""
    p.add_argument(
        "--preset",
        dest="selector_options",
        action=_Preset,
        choices=PRESETS,
        metavar="NAME",
        help=f"the selector's preset for {what}: {', '.join(PRESETS)} (default: {default}). "
        f"{describe()}",
    )
    for name in ("fast", "swarm"):
        p.add_argument(
            f"--{name}",
            dest="selector_options",
            action=_Preset,
            const=name,
            nargs=0,
            help=f"--preset {name}",
        )
    p.add_argument(
        "--selector-option",
        "-o",
        dest="selector_options",
        type=_selector_option,
        action="append",
        metavar="KEY=VALUE",
        help=f"one field of the selector's configuration for {what}, over the preset, as the "
        "scenario key selector_options takes it, e.g. closing_guard=false or margin=0.05 "
        "(the fields and their ranges: vo3d_opt.config); repeatable; overrides the scenario's",
    )


def with_options(sc: Scenario, pairs: list[tuple[str, Any]] | None) -> Scenario:
    """The scenario with ``--preset`` and ``-o`` merged into its ``selector_options``."""
    if not pairs:
        return sc
    try:
        options = check_selector_options(dict(pairs), "--selector-option")
        log.info("selector options from the command line: %s", options)
        return scenario_variant(sc, selector_options=options)
    except ScenarioError as exc:
        raise UsageError(str(exc)) from None


def selector(sc: Scenario, formulation: str | None, solver: str | None) -> tuple[Any, str, str]:
    """The scenario's selector (``scenario_selector``); a bad name is a ``UsageError``."""
    try:
        return scenario_selector(sc, formulation, solver)
    except MissingExtra:  # its own line, naming the extra (exit 2 all the same)
        raise
    except (ValueError, TypeError) as exc:
        f = formulation or sc.formulation or DEFAULT_FORMULATION
        s = solver or sc.solver or DEFAULT_SOLVERS.get(f)
        what = f"formulation {f!r}" + (f", solver {s!r}" if s else "")
        raise UsageError(f"{what}: {exc}") from None


# --------------------------------------------------------------------------- stdout


def _c_flush() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # pragma: no cover - no libc (Windows)
        pass


@contextlib.contextmanager
def stdout_to_stderr() -> Iterator[None]:
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
