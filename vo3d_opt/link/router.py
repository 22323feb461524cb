"""The swarm's shared network for ``vo3d sitl``: a UDP hub on 127.0.0.1, one process.

Two ports: vehicles (and whatever plays a radio on the vehicles' side: the fault injector)
send to the first, links to the second. Every datagram from the vehicles' side goes to every
endpoint of the links' side and the other way round, unparsed and unchanged, as a broadcast
radio or ``mavlink-router`` would carry it: every link hears every vehicle's telemetry (its
own and its peers'), every vehicle hears every link's set-points and keeps those addressed to
it. An endpoint is known from its first datagram.

Run as ``python -m vo3d_opt.link.router``: it prints ``{"vehicles": PORT, "links": PORT}``
on stdout once bound, then forwards until SIGTERM or SIGINT.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import sys
from typing import Any

HOST = "127.0.0.1"
#: Socket buffers (bytes): bursts of telemetry must not be dropped by the kernel.
BUFFER = 1 << 21


def _socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for opt in (socket.SO_RCVBUF, socket.SO_SNDBUF):
        s.setsockopt(socket.SOL_SOCKET, opt, BUFFER)
    s.bind((HOST, 0))
    s.setblocking(False)
    return s


class Router:
    def __init__(self) -> None:
        self.vehicles, self.links = _socket(), _socket()
        self.ends: dict[socket.socket, set[Any]] = {self.vehicles: set(), self.links: set()}
        self.other = {self.vehicles: self.links, self.links: self.vehicles}
        self.stop = False
        self.forwarded = 0

    def ports(self) -> dict[str, int]:
        return {"vehicles": self.vehicles.getsockname()[1], "links": self.links.getsockname()[1]}

    def run(self) -> None:
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)
        parent = os.getppid()
        while not self.stop and os.getppid() == parent:  # vo3d sitl killed: do not outlive it
            ready, _, _ = select.select([self.vehicles, self.links], [], [], 0.2)
            for side in ready:
                self._drain(side)

    def _drain(self, side: socket.socket) -> None:
        out = self.other[side]
        while True:
            try:
                data, addr = side.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # an ICMP error queued for an endpoint gone: skip it
                continue
            self.ends[side].add(addr)
            for end in self.ends[out]:
                try:
                    out.sendto(data, end)
                    self.forwarded += 1
                except OSError:
                    pass

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.stop = True


def run_router() -> int:
    router = Router()
    print(json.dumps(router.ports()))
    sys.stdout.flush()
    router.run()
    return 0


if __name__ == "__main__":
    sys.exit(run_router())
