"""The argument types of ``vo3d link`` and ``vo3d sitl`` (``argparse`` ``type=``): each
refuses what the loops cannot run on with an ``ArgumentTypeError``, which the parser turns into
exit status 2 and one line naming the option."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from vo3d_opt.link.frames import parse_origin


def positive(text: str) -> float:
    """A finite number > 0 (the timeouts, ADS-B traffic's zone and speed)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number")
    return value


def number_in(low: float, high: float, unit: str) -> Callable[[str], float]:
    """An ``argparse`` type: a number from ``low`` to ``high``. Rates and time scales are
    bounded so that every period the loops wait stays one ``select()`` can wait and one that
    ends (a NaN or infinite clock never times out)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not a number from {low:g} to {high:g}{unit}"
            )
        return value

    return parse


#: The largest ``--epoch`` (s): a ``time.monotonic()`` reading, seconds since boot; beyond about
#: 1e16 a clock of monotonic() - epoch no longer moves, and the link would never time out.
EPOCH_LIMIT = 1e9

epoch = number_in(-EPOCH_LIMIT, EPOCH_LIMIT, " s (a time.monotonic() reading)")
rate = number_in(0.01, 1000.0, " Hz")
time_scale = number_in(0.001, 1000.0, "")
sim_rate = number_in(0.01, 10000.0, " Hz")


def int_in(low: int, high: int, what: str) -> Callable[[str], int]:
    """An ``argparse`` type: an integer from ``low`` to ``high``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = low - 1
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text!r} is not {what} ({low} to {high})")
        return value

    return parse


system_id = int_in(1, 255, "a system id")
component = int_in(0, 255, "a component id")
baud = int_in(1, 100_000_000, "a baud rate")


def origin(text: str) -> tuple[float, float, float]:
    try:
        return parse_origin(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def triple(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(p) for p in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: expected X,Y,Z in metres")
    return values


def system_ids(text: str) -> dict[str, int]:
    out: dict[str, int] = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise argparse.ArgumentTypeError(f"{item!r}: expected AGENT=SYSID")
        out[name.strip()] = system_id(value.strip())
    if len(set(out.values())) != len(out):
        raise argparse.ArgumentTypeError(f"{text!r}: two agents share a system id")
    return out
