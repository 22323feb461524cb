"""Log records of the package on stderr, as the command lines show them: info lines as they
are, the others prefixed with their level (errors with ``vo3d:``)."""

from __future__ import annotations

import logging
import sys


class ConsoleFormatter(logging.Formatter):
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
    handler.setFormatter(ConsoleFormatter())
    handler._vo3d_cli = True  # type: ignore[attr-defined]
    root.addHandler(handler)
    root.setLevel(level)
    root.propagate = False
