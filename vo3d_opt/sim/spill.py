"""Run records kept on disk: the arrays of a long run of a large swarm in one unlinked temporary
file, mapped into memory, whose pages the simulator and the metrics let go of as they go.

A 10,000-vehicle run of 2,600 steps records 26 million agent-steps of positions, velocities,
preferred velocities, statuses and times: more than 2 GB. Held in anonymous memory, all of it
stays resident until the run's record is dropped. Here each array is a view of a shared file
mapping: :meth:`Spill.drop` (``madvise(MADV_DONTNEED)``) unmaps the pages written so far from
the process, the page cache keeps their contents (the kernel writes them out when it needs the
memory) and the next read maps them back. The numbers are those of an in-memory record, bit
for bit: only where they live changes.

Linux only (:func:`spill_supported`): there ``MADV_DONTNEED`` unmaps the pages of a shared file
mapping at once and ``posix_fallocate`` reserves the file's blocks (elsewhere a full disk would
kill the process with a bus error in the middle of a run). A directory in memory (tmpfs, ramfs:
some systems mount ``/tmp`` so) would only move the record out of the process's count, not out
of memory: :func:`in_memory_fs` says so and the simulator does not spill there.
"""

from __future__ import annotations

import mmap
import os
import sys
import tempfile
from typing import Any

import numpy as np

#: Records whose allotment (steps the run may take x agents x bytes per agent-step) exceeds
#: this many bytes are spilled by default (``fly(spill=None)``).
SPILL_BYTES = 1 << 30


def array_bytes(shape: tuple[int, ...], dtype: Any) -> int:
    """Bytes of an array of ``shape`` and ``dtype``."""
    return int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize


#: File systems whose files live in memory.
MEMORY_FS = ("tmpfs", "ramfs")


def spill_supported() -> bool:
    """Whether this platform can spill: Linux, with ``madvise`` and ``posix_fallocate``."""
    return (
        sys.platform.startswith("linux")
        and hasattr(mmap, "MADV_DONTNEED")
        and hasattr(mmap.mmap, "madvise")
        and hasattr(os, "posix_fallocate")
    )


def spill_directory(directory: str | os.PathLike[str] | None) -> str:
    """The directory a spill file goes to: ``directory``, or the system's temporary one."""
    return os.path.realpath(tempfile.gettempdir() if directory is None else os.fspath(directory))


def in_memory_fs(directory: str, mounts: str | None = None) -> bool:
    """Whether ``directory`` (a real path) is on a file system held in memory: the type of the
    longest mount point that holds it in ``mounts`` (the text of ``/proc/self/mounts``, read
    when None; False when it cannot be read)."""
    if mounts is None:
        try:
            with open("/proc/self/mounts") as fh:
                mounts = fh.read()
        except OSError:
            return False
    best, fstype = "", ""
    for line in mounts.splitlines():
        fields = line.split()
        if len(fields) < 3:
            continue
        point, kind = fields[1], fields[2]
        point = point.replace("\\040", " ")
        inside = directory == point or directory.startswith(point.rstrip("/") + "/")
        if inside and len(point) >= len(best):
            best, fstype = point, kind
    return fstype in MEMORY_FS


class Spill:
    """The arrays ``specs`` (name: (shape, dtype)), zero-filled, each starting on a page of its
    own in one temporary file (``directory``: where, default the system's temporary
    directory; the file is unlinked at once, so it goes with the last array that maps it).
    Its blocks are reserved up front (``posix_fallocate``): a full disk raises ``OSError``
    here, not a bus error in the middle of a run. Linux only (:func:`spill_supported`)."""

    def __init__(
        self,
        specs: dict[str, tuple[tuple[int, ...], Any]],
        directory: str | os.PathLike[str] | None = None,
    ) -> None:
        page, offsets, end = mmap.PAGESIZE, {}, 0
        for name, (shape, dtype) in specs.items():
            offsets[name] = end
            end += -(-array_bytes(shape, dtype) // page) * page
        self.size = max(end, page)
        with tempfile.TemporaryFile(dir=directory) as fh:
            os.posix_fallocate(fh.fileno(), 0, self.size)
            self.map = mmap.mmap(fh.fileno(), self.size)  # MAP_SHARED; it keeps its own fd
        self.arrays = {
            name: np.frombuffer(
                self.map,
                dtype=dtype,
                count=int(np.prod(shape, dtype=np.int64)),
                offset=offsets[name],
            ).reshape(shape)
            for name, (shape, dtype) in specs.items()
        }

    def drop(self) -> None:
        """Unmap every page from the process (contents kept: the next read maps them back)."""
        self.map.madvise(mmap.MADV_DONTNEED, 0, self.size)
