"""What every results page under docs/results shares: the machine line at its top, the rows it
was rendered from, and how it is written.

The scripts of this folder run as scripts (``python benchmarks/NAME.py``), so they import this
module as ``from pages import ...``. A page names its machine, date and commit once, in the line
``machine_line()`` returns; the script that measures a page writes all of it, so that running
the script again writes the same page from the new measurements. A script that keeps its rows
(``write_rows``) can render its page again from them (``read_rows``) without measuring.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: The docs' results pages, which these benchmarks write.
RESULTS = ROOT / "docs" / "results"
#: Left out of the "uncommitted changes" check: the pages a run is rewriting.
_PAGES_PATHSPEC = ":(exclude)docs/results"


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True, text=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    return out.stdout.strip()


def commit() -> str:
    """HEAD's short hash, with " + uncommitted changes" when a tracked file differs from it or
    an untracked one is not ignored (the results pages themselves left out); "unknown" outside
    a git checkout."""
    head = _git("rev-parse", "--short", "HEAD")
    if head is None:
        return "unknown"
    dirty = _git("status", "--porcelain", "--", ".", _PAGES_PATHSPEC)
    return f"{head} + uncommitted changes" if dirty else head


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _load() -> str:
    if not hasattr(os, "getloadavg"):
        return "load average not available"
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} / {five:.2f} / {fifteen:.2f} (1 / 5 / 15 min) when written"


def machine_line(*extras: str, against: str | None = None) -> str:
    """The page's one line of provenance: CPU model and count, load average, Python and
    platform, ``extras`` (versions of what the page measures, e.g. ``"rvo23d 0.1.6"``), date
    and commit (and ``against``, the revision a page compares this code with)."""
    python = f"{platform.python_implementation()} {platform.python_version()}"
    what = [
        f"{_cpu_model()}, {os.cpu_count()} CPUs, {_load()}",
        f"{python} on {platform.platform()}",
        *extras,
    ]
    now = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    other = f" against `{against}`" if against else ""
    return f"**Machine** {' · '.join(what)} · **Date** {now} · **Commit** `{commit()}`{other}"


#: Options whose value is a path of the machine that ran the script, not the page's business.
PATH_OPTIONS = ("--out", "--results", "--out-root", "--pages", "--old-rows", "--save-old")


def command_line(hide: tuple[str, ...] = PATH_OPTIONS) -> str:
    """This script's command line as a page quotes it, ``python benchmarks/NAME.py ARGS``, the
    options of ``hide`` (where the page goes, where the runs are) and their values left out."""
    args, skip = [], False
    for arg in sys.argv[1:]:
        if skip:
            skip = False
        elif arg in hide:
            skip = True
        elif not arg.startswith(tuple(f"{h}=" for h in hide)):
            args.append(arg)
    return shlex.join(["python", f"benchmarks/{Path(sys.argv[0]).name}", *args])


def write_page(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` at once (a temporary file beside it, then renamed over it), so
    that a reader or an interrupted run never sees half a page; a final newline added."""
    write_atomic(path, text.rstrip("\n") + "\n")


def write_atomic(path: Path, text: str) -> None:
    """``text`` into ``path`` through a temporary file renamed over it, with the mode a new
    file gets (the temporary file's own is private)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(
        "w", encoding="utf-8", dir=path.parent, delete=False, prefix=f".{path.name}.", suffix=".tmp"
    ) as tmp:
        tmp.write(text)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp.name, 0o666 & ~umask)
    os.replace(tmp.name, path)


def write_rows(
    path: Path, rows: Iterable[dict[str, Any]], *, machine: str, command: str | list[str]
) -> None:
    """The rows a page is rendered from, as JSON lines: first the header ``{"machine": LINE,
    "commit": ..., "command": ...}`` (the command, or the commands of a page run in parts),
    then one row a line."""
    head = {"machine": machine, "commit": commit(), "command": command}
    lines = [json.dumps(head), *(json.dumps(row) for row in rows)]
    write_atomic(path, "\n".join(lines) + "\n")


def read_rows(path: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(header, rows) of a file ``write_rows`` wrote; a file of rows alone gives an empty
    header."""
    head: dict[str, Any] = {}
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.strip():
            continue
        record = json.loads(line)
        if "machine" in record and set(record) <= {"machine", "commit", "command"}:
            head = record
        else:
            rows.append(record)
    return head, rows
