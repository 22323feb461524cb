"""``vo3d compile``: the ahead-of-time decision kernels (``formulations/aot.py``)."""

from __future__ import annotations

import argparse
from typing import Any

from vo3d_opt.types import one_line

from .common import EXIT_FAIL, EXIT_OK, log


def add_compile_parser(sub: Any, common: list[argparse.ArgumentParser]) -> None:
    comp = sub.add_parser(
        "compile",
        parents=common,
        help="compile the decision kernels of select() and select_many() ahead of time",
        description="Compile the decision kernels of select() and select_many() ahead of time "
        "(numba.pycc) into the installed package, so that a first select() in a new process "
        "does not wait for numba's JIT compiler (about 30 s). A module built from other "
        "sources, Python, numba, numpy or another CPU is ignored: run it again after an edit "
        "or an upgrade (make does). The package's folder must be writable.",
    )
    comp.add_argument(
        "--check",
        action="store_true",
        help="only say whether select() would run an ahead-of-time kernel, and why (exit 1 if not)",
    )
    comp.set_defaults(func=cmd_compile)


def cmd_compile(args: argparse.Namespace) -> int:
    """Build the ahead-of-time decision kernel (formulations/aot.py) next to the package."""
    from vo3d_opt.formulations import aot

    if args.check:
        compiled, note = aot.load()
        print(note)
        return EXIT_OK if compiled is not None else EXIT_FAIL
    log.info("compiling the decision kernels ahead of time (about 40 s)...")
    try:
        path, seconds = aot.build()
    except (RuntimeError, OSError) as exc:
        log.error("%s", one_line(exc))
        return EXIT_FAIL
    compiled, note = aot.load()
    if compiled is None:
        log.error("built %s, but it does not load: %s", path, note)
        return EXIT_FAIL
    print(f"built {path} in {seconds:.0f} s: select() and select_many() run it from now on")
    return EXIT_OK
