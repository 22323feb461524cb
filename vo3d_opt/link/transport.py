"""One MAVLink connection (pymavlink's ``mavlink_connection``), read without blocking, every
packet it refuses counted by reason.

pymavlink parses with ``robust_parsing``: what it cannot use comes out as ``BAD_DATA`` with a
reason, which :func:`classify` turns into a short key (``bad_prefix``: bytes that start no
packet; ``bad_crc``; ``malformed``: a wrong length, flags or payload; ``unsigned`` and
``bad_signature`` with signing on). Over UDP a datagram carries whole packets, so the bytes a
datagram leaves unparsed are dropped with it (``truncated``) rather than prepended to the next
datagram: garbage cannot swallow the next good packet.

Signing (MAVLink 2): with a key every outgoing packet is signed and every incoming packet
must carry a valid signature (pymavlink checks the SHA-256 signature and the replay
timestamp); none is let through unsigned.
"""

from __future__ import annotations

import contextlib
import io
import logging
import select
import time
from collections import Counter
from typing import Any

from vo3d_opt.link.messages import mavlink

log = logging.getLogger("vo3d_opt.link")

#: Most reads in one :meth:`MavlinkPort.receive` call (a flood cannot starve the loop).
MAX_READS = 2000


def classify(reason: str, bad_signatures: int, before: int) -> str:
    """The count key of a ``BAD_DATA`` reason (``bad_signatures``: pymavlink's count of wrong
    signatures now, ``before``: before this packet)."""
    text = reason.lower()
    if "signature" in text:
        return "bad_signature" if bad_signatures > before else "unsigned"
    if "prefix" in text:
        return "bad_prefix"
    if "crc" in text:
        return "bad_crc"
    return "malformed"


def _refuse_unsigned(mav: Any, msg_id: int) -> bool:
    return False


class MavlinkPort:
    """A pymavlink connection to ``url`` sending as (``source_system``, ``source_component``);
    ``signing_key``: 32 bytes, sign everything sent and refuse what is not signed with it."""

    def __init__(
        self,
        url: str,
        *,
        source_system: int,
        source_component: int,
        signing_key: bytes | None = None,
        link_id: int = 0,
        baud: int = 57600,
    ) -> None:
        mavlink()
        from pymavlink import mavutil

        said = io.StringIO()
        # pymavlink prints its connection retries on stdout, which carries the summary; the
        # redirect is the process's while the connection is made (a thread of the caller's
        # that prints meanwhile goes to the debug log too)
        try:
            with contextlib.redirect_stdout(said):
                self.conn = mavutil.mavlink_connection(
                    url, baud=baud, source_system=source_system, source_component=source_component
                )
        finally:
            for line in said.getvalue().splitlines():
                log.debug("pymavlink: %s", line)
        self.mav = self.conn.mav
        self.mav.robust_parsing = True
        self.datagrams = isinstance(self.conn, mavutil.mavudp | mavutil.mavmcast)
        # a listening stream's recv gives b"" once its peer closed ("" while nothing is there)
        self.listening = isinstance(self.conn, mavutil.mavtcpin)
        self.signed = signing_key is not None
        if signing_key is not None:
            self.conn.setup_signing(
                signing_key,
                sign_outgoing=True,
                allow_unsigned_callback=_refuse_unsigned,
                link_id=link_id,
            )
        self.rejected: Counter[str] = Counter()
        self.received = 0
        #: A stream (TCP) the other end closed: pymavlink's own handlers would print on stdout
        #: and, without autoreconnect, leave a socket that reads as ready for ever.
        self.closed = False
        if hasattr(self.conn, "handle_eof"):
            self.conn.handle_eof = self.conn.handle_disconnect = self._on_closed

    def _on_closed(self) -> None:
        self.closed = True

    def fileno(self) -> int | None:
        fd = getattr(self.conn, "fd", None)
        return fd if isinstance(fd, int) and fd >= 0 else None

    def wait(self, timeout: float) -> None:
        """Block until data may be there, at most ``timeout`` s."""
        fd = self.fileno()
        if self.closed:  # a closed stream is always "ready": wait the time out instead
            time.sleep(max(timeout, 0.0))
            return
        if fd is None:
            time.sleep(min(max(timeout, 0.0), 0.001))
            return
        select.select([fd], [], [], max(timeout, 0.0))

    def receive(self) -> list[Any]:
        """Every message that arrived since the last call (good ones only; the others are
        counted in ``rejected``)."""
        out: list[Any] = []
        for _ in range(MAX_READS):
            if self.closed:
                break
            try:
                data = self.conn.recv(65535) if not self.datagrams else self.conn.recv()
            except OSError as exc:  # reset by the other end (pymavlink re-raises), unplugged...
                log.warning("connection lost: %s", exc)
                self.closed = True
                break
            if not data:
                self.closed = self.closed or (self.listening and isinstance(data, bytes))
                break
            out += self._parse(bytes(data) if isinstance(data, bytes | bytearray) else data)
            if self.datagrams:
                self._drop_partial()
        return out

    def _parse(self, data: Any) -> list[Any]:
        """The good messages in ``data``, one packet at a time (so that each wrong signature
        is told from an unsigned packet by pymavlink's count of wrong signatures)."""
        good = []
        signing = self.mav.signing
        before = signing.badsig_count
        msg = self.mav.parse_char(data)
        while msg is not None:
            kind = msg.get_type()
            if kind == "BAD_DATA":
                self.rejected[classify(str(msg.reason), signing.badsig_count, before)] += 1
            elif kind.startswith("UNKNOWN_"):
                self.rejected["unknown_message"] += 1
            else:
                self.received += 1
                good.append(msg)
            before = signing.badsig_count
            msg = self.mav.parse_char(b"")
        return good

    def _drop_partial(self) -> None:
        """Forget the bytes of a datagram that started a packet it did not finish."""
        mav = self.mav
        if mav.buf_len() > 0:
            self.rejected["truncated"] += 1
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = mavlink().HEADER_LEN_V1 + 2

    def send(self, msg: Any) -> None:
        self.mav.send(msg)

    def close(self) -> None:
        try:
            self.conn.close()
        except OSError:
            pass
