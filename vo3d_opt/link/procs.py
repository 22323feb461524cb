"""The processes ``vo3d sitl`` starts, and how it stops them.

The router is a program of its own (``router.py`` run as a file: the standard library only).
The vehicles and the links are forked from ``vo3d sitl`` itself once it has imported the
package, each in a session of its own with its stdout on a pipe: each is a process of its own,
as on separate computers, without paying the package's imports again (about 0.7 s of CPU per
process, most of a small run's start on two cores). A forked link runs exactly what
``vo3d link`` runs (``vo3d_opt.link.command.link_main``). Forking needs a process without
other threads:
:class:`Proc` starts its stdout reader thread only when asked (:meth:`Proc.read_on`), after
every fork.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO

#: Signals a forked child gets back to their defaults (the orchestrator handles them its way).
_RESET = (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1, signal.SIGUSR2)


class Forked:
    """``target()`` run in a forked child (its return value the exit status), in a new
    session, stdout to a pipe (``stdout``), stdin closed; ``Popen``'s ``pid``, ``poll``,
    ``wait``."""

    def __init__(self, target: Callable[[], int]) -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child (its effects are what the tests see)
            os.close(read)
            _child(target, write)
        os.close(write)
        self.pid = pid
        self.stdout: IO[str] = os.fdopen(read, "r")
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if deadline is not None and time.monotonic() > deadline:
                raise subprocess.TimeoutExpired(str(self.pid), timeout or 0.0)
            time.sleep(0.01)
        assert self.returncode is not None
        return self.returncode


def _child(target: Callable[[], int], write: int) -> None:  # pragma: no cover - in the child
    code = 1
    try:
        os.setsid()
        for sig in _RESET:
            signal.signal(sig, signal.SIG_DFL)
        os.dup2(write, 1)
        os.close(write)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        sys.stdout = os.fdopen(1, "w", buffering=1)
        code = int(target())
    except BaseException:  # everything ends here: the child must never return into the parent
        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
        finally:
            os._exit(code)


@dataclass
class Proc:
    """A started process (``handle``: a ``Popen`` or a :class:`Forked`); a thread keeps its
    stdout's lines in ``lines`` once :meth:`read_on` is called."""

    name: str
    handle: subprocess.Popen[str] | Forked
    lines: list[str] = field(default_factory=list)
    reader: threading.Thread | None = None

    @property
    def pid(self) -> int:
        return self.handle.pid

    @property
    def stdout(self) -> IO[str]:
        assert self.handle.stdout is not None
        return self.handle.stdout

    def alive(self) -> bool:
        return self.handle.poll() is None

    def read_on(self) -> None:
        def pump() -> None:
            for line in self.stdout:
                self.lines.append(line)

        self.reader = threading.Thread(target=pump, name=self.name, daemon=True)
        self.reader.start()

    def signal(self, sig: int) -> None:
        """``sig`` to the process's session (its own: it leads it)."""
        if self.alive():
            try:
                os.killpg(self.pid, sig)
            except ProcessLookupError:
                pass

    def collect(self, deadline: float) -> None:
        """Wait until ``deadline`` (time.monotonic), then SIGKILL; the last of its output."""
        try:
            self.handle.wait(timeout=max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            self.signal(signal.SIGKILL)
            self.handle.wait()
        if self.reader is not None:
            self.reader.join(timeout=5.0)
