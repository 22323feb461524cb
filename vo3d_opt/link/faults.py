"""Faults ``vo3d sitl --fault`` injects into a run, each at a time of the run's clock.

* ``cut:AGENT:AT:SECONDS``: AGENT's vehicle sends nothing (telemetry, heartbeats) for SECONDS;
* ``kill:AGENT:AT``: AGENT's link process is killed (SIGKILL: no goodbye);
* ``garbage:AT:COUNT``: COUNT datagrams of random bytes that start no MAVLink packet;
* ``malformed:AT:COUNT``: COUNT each of a packet with a wrong checksum, a packet cut short,
  and a well-formed ``GLOBAL_POSITION_INT`` placing a vehicle outside the globe;
* ``spoof:AGENT:AT:COUNT``: COUNT ``GLOBAL_POSITION_INT`` claiming AGENT's system id, 10 km
  off where it is;
* ``foreign:AT:COUNT``: COUNT position reports from a system id no agent has (250);
* ``unsigned:AT:COUNT`` / ``badsig:AT:COUNT``: COUNT unsigned / wrongly signed reports from
  a configured system (they count as rejected only when the run signs).

Every injected datagram enters the network on the vehicles' side of the router, as a radio
would carry it, so every link hears it.
"""

from __future__ import annotations

import argparse
import socket
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

FAULT_HELP = (
    "inject a fault (repeatable): cut:AGENT:AT:SECONDS, kill:AGENT:AT, garbage:AT:COUNT, "
    "malformed:AT:COUNT, spoof:AGENT:AT:COUNT, foreign:AT:COUNT, unsigned:AT:COUNT, "
    "badsig:AT:COUNT (AT in seconds of the run; docs/link.md)"
)
#: kind -> does it name an agent, and what its last field is
_FORMS = {
    "cut": (True, "seconds"),
    "kill": (True, None),
    "garbage": (False, "count"),
    "malformed": (False, "count"),
    "spoof": (True, "count"),
    "foreign": (False, "count"),
    "unsigned": (False, "count"),
    "badsig": (False, "count"),
}
FOREIGN_SYSTEM = 250
#: MAVLink's packet markers (v1, v2) and the v0.9 one: garbage never holds them.
MARKERS = (0xFE, 0xFD, 0x55)


@dataclass(frozen=True)
class Fault:
    kind: str
    at: float
    agent: str | None = None
    amount: float = 0.0

    def __str__(self) -> str:
        parts = [self.kind, *([self.agent] if self.agent else []), f"{self.at:g}"]
        return ":".join(parts + ([f"{self.amount:g}"] if self.kind != "kill" else []))


def parse_fault(text: str) -> Fault:
    """A :class:`Fault` from its spec (``argparse`` type: errors name the spec)."""
    kind, *rest = text.split(":")
    if kind not in _FORMS:
        raise argparse.ArgumentTypeError(f"{text!r}: unknown fault {kind!r} ({', '.join(_FORMS)})")
    named, last = _FORMS[kind]
    want = int(named) + 1 + int(last is not None)
    if len(rest) != want:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {want} fields after {kind}")
    agent = rest.pop(0) if named else None
    try:
        numbers = [float(x) for x in rest]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: AT and its amount are numbers") from None
    if not all(np.isfinite(numbers)) or min(numbers) < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: AT and its amount must be >= 0")
    amount = numbers[1] if last else 0.0
    if last == "count" and (amount != int(amount) or amount < 1):
        raise argparse.ArgumentTypeError(f"{text!r}: COUNT must be a whole number >= 1")
    return Fault(kind=kind, at=numbers[0], agent=agent, amount=amount)


class Injector:
    """Sends the datagrams of the packet faults to the router's vehicles port ``port``.
    ``system_ids``: agent -> system id; ``frame``: the run's geodetic frame; ``key``: the
    run's signing key (None: unsigned run)."""

    def __init__(
        self, port: int, system_ids: dict[str, int], frame: Any, key: bytes | None
    ) -> None:
        self.addr = ("127.0.0.1", port)
        self.ids, self.frame, self.key = system_ids, frame, key
        self.rng = np.random.default_rng(42)
        self.sent = 0

    def _mav(self, system: int, key: bytes | None) -> Any:
        from vo3d_opt.link.messages import mavlink

        mav = mavlink().MAVLink(None, srcSystem=system, srcComponent=1)
        if key is not None:
            mav.signing.secret_key = key
            mav.signing.sign_outgoing = True
            mav.signing.link_id = 7
            mav.signing.timestamp = int((time.time() - 1420070400) * 1e5)
        return mav

    def _report(self, mav: Any, p: Any) -> bytes:
        from vo3d_opt.link.messages import global_position

        msg = global_position(mav, self.frame, np.asarray(p, float), np.zeros(3), 0)
        return bytes(msg.pack(mav))

    def datagrams(self, fault: Fault) -> list[bytes]:
        n = int(fault.amount)
        some = next(iter(self.ids.values()))
        if fault.kind == "garbage":
            return [self._garbage() for _ in range(n)]
        if fault.kind == "malformed":
            return [d for _ in range(n) for d in self._malformed(some)]
        if fault.kind == "spoof":
            assert fault.agent is not None
            mav = self._mav(self.ids[fault.agent], self.key)
            return [self._report(mav, (1e4, 1e4, 20.0)) for _ in range(n)]
        if fault.kind == "foreign":
            mav = self._mav(FOREIGN_SYSTEM, self.key)
            return [self._report(mav, (0.0, 0.0, 20.0)) for _ in range(n)]
        if fault.kind == "badsig":
            mav = self._mav(some, bytes(range(32)) if self.key != bytes(range(32)) else bytes(32))
            return [self._report(mav, (0.0, 0.0, 20.0)) for _ in range(n)]
        assert fault.kind == "unsigned"
        mav = self._mav(some, None)
        return [self._report(mav, (0.0, 0.0, 20.0)) for _ in range(n)]

    def _garbage(self) -> bytes:
        data = self.rng.integers(0, 256, size=int(self.rng.integers(8, 200)), dtype=np.uint8)
        for marker in MARKERS:
            data[data == marker] = 0x00
        return data.tobytes()

    def _malformed(self, system: int) -> list[bytes]:
        from vo3d_opt.link.messages import global_position

        mav = self._mav(system, self.key)
        good = self._report(mav, (0.0, 0.0, 20.0))
        bad_crc = bytearray(good)
        crc_at = len(good) - (2 + (13 if self.key is not None else 0))
        bad_crc[crc_at] ^= 0xFF
        cut = good[: len(good) // 2]
        far = self.frame.to_world(0.0, 0.0, 0.0)  # any real point, then moved off the globe
        msg = global_position(mav, self.frame, far, np.zeros(3), 0)
        msg.lat = 95 * 10_000_000
        impossible = bytes(msg.pack(mav, force_mavlink1=False))
        return [bytes(bad_crc), cut, impossible]

    def send(self, fault: Fault) -> int:
        """Send the fault's datagrams; how many."""
        packets = self.datagrams(fault)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for data in packets:
                s.sendto(data, self.addr)
                time.sleep(0.0005)  # a radio's pace, not a burst the kernel would drop
        self.sent += len(packets)
        return len(packets)
