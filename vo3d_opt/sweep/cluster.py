"""The Dask side of a sweep: the client (a local cluster or an existing scheduler), the warm-up
plugin and the bounded submission loop.

A task flies a batch of encounters (:func:`~vo3d_opt.sweep.flight.run_encounters`, side by
side where it can); at most ``in_flight`` tasks are on the cluster at a time, more are
submitted as others complete (collected with ``as_completed``). A task whose workers died
(``KilledWorker`` after the scheduler's allowed failures) or that failed in any other way is
split into its single encounters, and an encounter that fails alone becomes a row with its
``error``: no encounter is dropped and the loop goes on.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import signal
import socket
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from vo3d_opt.extras import needs
from vo3d_opt.generators import Family
from vo3d_opt.sweep.flight import Method, error_line, run_encounters, warm

with needs("sweep", "vo3d sweep"):
    from distributed import Client, LocalCluster, WorkerPlugin, as_completed
    from tqdm import tqdm

CONNECT_TIMEOUT = 20.0  # s, to reach a --scheduler and to see its first worker


class ConnectError(OSError):
    """The scheduler at the given address cannot be reached or has no worker."""


class WarmUp(WorkerPlugin):
    """Runs :func:`~vo3d_opt.sweep.flight.warm` on every worker when registered and on every
    worker that joins later (e.g. restarted after a death), in a thread so that the worker
    keeps answering the scheduler while it imports and loads the selector's backends."""

    name = "vo3d-sweep-warm-up"

    def __init__(self, method: Method, extra: dict[str, Any] | None = None) -> None:
        self.method = method
        self.extra = dict(extra or {})

    async def setup(self, worker: Any) -> None:
        await asyncio.get_running_loop().run_in_executor(None, warm, self.method, self.extra)


#: The addresses ``--scheduler`` takes: Dask's TCP and TLS transports.
SCHEDULER_ADDRESS = re.compile(r"^(tcp|tls)://[^/\s:]+:[0-9]{1,5}$")


def check_address(scheduler: str) -> None:
    """``ConnectError`` unless ``scheduler`` is an address ``--scheduler`` takes."""
    if not SCHEDULER_ADDRESS.match(scheduler) or not 0 < int(scheduler.rsplit(":", 1)[1]) < 65536:
        raise ConnectError(
            f"{scheduler!r} is not a scheduler address (tcp://HOST:PORT or tls://HOST:PORT, "
            "PORT 1 to 65535)"
        )


def check_reachable(scheduler: str) -> None:
    """``ConnectError`` unless something accepts a TCP connection at a ``tcp://`` scheduler's
    host and port: a refused address fails at once, not after Dask's retries of
    ``CONNECT_TIMEOUT``. (The scheduler logs the bare connection at INFO level. A ``tls://``
    one is left to Dask: it would log a failed handshake as a warning.)"""
    transport, address = scheduler.split("://", 1)
    if transport != "tcp":
        return
    host, port = address.rsplit(":", 1)
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT).close()
    except (OSError, OverflowError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise ConnectError(f"cannot connect to {scheduler}: {reason}") from None


@contextlib.contextmanager
def client_for(workers: int, scheduler: str | None, allowed_failures: int) -> Iterator[Client]:
    """A client of the scheduler at ``scheduler``, or of a new local cluster of ``workers``
    processes with one thread each (closed on exit), its HTTP server on a free local port."""
    import dask

    if scheduler:
        check_address(scheduler)
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except Exception as exc:  # noqa: BLE001 - any failure to connect is one line
            raise ConnectError(f"cannot connect to {scheduler}: {error_line(exc)}") from None
        try:
            try:
                client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
            except TimeoutError:
                raise ConnectError(f"{scheduler} has no worker") from None
            yield client
        finally:
            client.close()
        return
    with dask.config.set({"distributed.scheduler.allowed-failures": allowed_failures}):
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            # the local workers' own logs: a worker that outlives its scheduler after a Ctrl-C
            # logs its failed heartbeats as errors; what matters of a worker reaches the
            # client as a task's error or a lost worker
            silence_logs=logging.CRITICAL,
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        )
    try:
        with Client(cluster) as client:
            client.register_plugin(_LocalWorker())
            yield client
    except KeyboardInterrupt:
        # the cluster is torn down mid-task: distributed's own logs of it are no news
        logging.getLogger("distributed").setLevel(logging.CRITICAL)
        raise
    finally:
        cluster.close()


class _LocalWorker(WorkerPlugin):
    """A worker of the local cluster leaves Ctrl-C to the client, which stops the cluster: the
    terminal sends SIGINT to every process of the command, and a worker interrupted inside a
    task prints a traceback of it."""

    async def setup(self, worker: Any) -> None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _error_row(
    fam: Family, seed: int, index: int, method: Method, exc: BaseException
) -> dict[str, Any]:
    return {
        "family": fam.name,
        "seed": seed,
        "index": index,
        "method": method.name,
        "error": error_line(exc),
        "worker": None,
    }


def _tally(counts: dict[str, int], row: dict[str, Any]) -> None:
    counts["errors"] += row.get("error") is not None
    counts["collisions"] += (row.get("collisions") or 0) > 0
    counts["intrusions"] += (
        (row.get("pz_intrusions") or 0) + (row.get("obstacle_pz_intrusions") or 0)
    ) > 0


@dataclass(frozen=True)
class Work:
    """What to fly: encounters ``indices`` of ``fam`` with ``seed`` and ``method``, ``batch``
    of them per task, at most ``in_flight`` tasks on the cluster at a time."""

    fam: Family
    seed: int
    method: Method
    indices: list[int]
    batch: int
    in_flight: int


def submit_all(
    client: Client,
    work: Work,
    bar: tqdm,
    sink: Callable[[list[dict[str, Any]]], None] | None = None,
) -> list[dict[str, Any]]:
    """Every encounter's row (in completion order), handed to ``sink`` as each task ends.

    A task whose worker died as often as the scheduler allows (``KilledWorker``) or that
    failed in any other way is split into single encounters, flown again: only an encounter
    that fails alone becomes a row with its ``error``, never one that shared its task."""
    idx = work.indices
    queue = deque(idx[i : i + work.batch] for i in range(0, len(idx), work.batch))
    chunk_of: dict[Any, list[int]] = {}  # a future's key -> its encounters
    done = as_completed()
    rows: list[dict[str, Any]] = []
    counts = {"collisions": 0, "intrusions": 0, "errors": 0}

    def submit() -> None:
        chunk = queue.popleft()
        fut = client.submit(run_encounters, work.fam, work.seed, chunk, work.method, pure=False)
        chunk_of[fut.key] = chunk
        done.add(fut)

    for _ in range(min(work.in_flight, len(queue))):
        submit()
    for fut in done:
        chunk = chunk_of.pop(fut.key)
        try:
            got = fut.result()
        except Exception as exc:  # noqa: BLE001 - KilledWorker, lost scheduler, ...
            if len(chunk) > 1:
                queue.extendleft([i] for i in reversed(chunk))
                got = []
            else:
                got = [_error_row(work.fam, work.seed, chunk[0], work.method, exc)]
        fut.release()
        while queue and len(chunk_of) < work.in_flight:
            submit()
        if got:
            rows += got
            if sink is not None:
                sink(got)
            for row in got:
                _tally(counts, row)
            bar.set_postfix(counts, refresh=False)
            bar.update(len(got))
    return rows
