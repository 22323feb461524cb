"""The threads of ``select_many``: how many a call may use, and the helpers kept from one call
to the next."""

from __future__ import annotations

import numbers
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

_pool_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None


def _workers(n: int) -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None or _pool._max_workers < n:  # noqa: SLF001 - grow to the threads asked for
            _pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="vo3d-swarm")
        return _pool


def cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def thread_count(threads: Any) -> int:
    """``threads`` checked (an integer in [1, ``cores()``]); None: every core."""
    limit = cores()
    if threads is None:
        return limit
    if (
        not isinstance(threads, numbers.Integral)
        or isinstance(threads, bool)
        or not 1 <= int(threads) <= limit
    ):
        raise ValueError(
            f"threads: must be an integer in [1, {limit}] (the cores this process may use), "
            f"got {threads!r}"
        )
    return int(threads)
