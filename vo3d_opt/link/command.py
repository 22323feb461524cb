"""The ``vo3d link`` and ``vo3d sitl`` command lines: :func:`add_parsers` adds both to
``vo3d``'s subcommands; :func:`cmd_link` and :func:`cmd_sitl` run them.

Bad arguments and files exit with status 2 and one line on stderr naming the argument; a
missing ``[link]`` extra says so the same way.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from vo3d_opt.extras import MissingExtra, check
from vo3d_opt.link import arguments as arg
from vo3d_opt.link.frames import parse_origin
from vo3d_opt.link.messages import AUTOPILOTS

log = logging.getLogger("vo3d_opt.link.command")
EXIT_USAGE = 2
#: PX4 SITL's default home (Zurich), used as the world's origin by ``vo3d sitl``.
SITL_ORIGIN = "47.397742,8.545594,488.0"

LINK_DESCRIPTION = """\
Fly one vehicle of a scenario through its autopilot over MAVLink: read its state and its
neighbours' from the MAVLink network, decide with the scenario's selector at --rate, and send
velocity set-points (SET_POSITION_TARGET_LOCAL_NED, MAV_FRAME_LOCAL_NED, velocity only) in
offboard (PX4) or guided (ArduPilot) mode. Prints a JSON summary on stdout when it stops
(arrival, --max-time, SIGINT, SIGTERM), after braking and asking the autopilot to hold.

Connecting to an autopilot (details: docs/link.md):
  PX4 SITL:        --connect udpin:0.0.0.0:14540 (the offboard API port), --autopilot px4
  ArduPilot SITL:  --connect tcp:127.0.0.1:5762 or udpin:0.0.0.0:14550, --autopilot ardupilot
  real vehicle:    --connect /dev/ttyACM0 --baud 921600 (or the companion's serial port or a
                   mavlink-router UDP endpoint that also carries the other vehicles' traffic)
Give each vehicle a distinct system id (PX4 MAV_SYS_ID, ArduPilot SYSID_THISMAV) and list
them with --system-ids; set the set-point loss failsafe (PX4 COM_OF_LOSS_T, COM_OBL_RC_ACT;
ArduPilot GUID_TIMEOUT) and use --signing-key on any radio link."""

SITL_DESCRIPTION = """\
A test harness: fly every agent of a scenario as separate processes over real MAVLink on
127.0.0.1: one simulated vehicle per agent (the scenario's dynamics, PX4-like offboard
interface), one `vo3d link` per agent that avoids, agents with avoids: false flying straight
and heard as ADS-B traffic, and a router sharing every vehicle's telemetry with every link.
Prints the summary of `vo3d run` (and writes its files with --out) from the vehicles' logged
states; every process is stopped on exit, on error and on Ctrl-C."""


def _add(p: argparse.ArgumentParser, *flags: str, **kw: Any) -> None:
    p.add_argument(*flags, **kw)


def _add_link(sub: Any, parents: Sequence[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "link",
        parents=list(parents),
        help="fly one vehicle of a scenario through its autopilot (MAVLink)",
        description=LINK_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add(
        p,
        "--connect",
        required=True,
        metavar="URL",
        help="pymavlink connection string: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, "
        "tcpin:HOST:PORT, or a serial device (/dev/ttyACM0, with --baud)",
    )
    _add(
        p,
        "--scenario",
        required=True,
        metavar="FILE",
        help="the scenario (a YAML file or a bundled name): goal, limits, obstacles, r_pz",
    )
    _add(p, "--agent", required=True, metavar="ID", help="the scenario agent this vehicle is")
    _add(
        p,
        "--rate",
        type=arg.rate,
        default=10.0,
        metavar="HZ",
        help="decisions and set-points per second, 0.01 to 1000 (default 10; PX4 needs more "
        "than 2)",
    )
    _add(
        p,
        "--signing-key",
        metavar="FILE",
        help="MAVLink 2 signing key (32 raw bytes or 64 hex digits): sign everything sent, "
        "refuse (and count) every packet not signed with it (default: no signing)",
    )
    _add(
        p,
        "--origin",
        type=arg.origin,
        metavar="LAT,LON,ALT",
        help="geodetic position (deg, deg, m above mean sea level) of the scenario's (0, 0, 0): "
        "states then come from GLOBAL_POSITION_INT; needed for ADS-B traffic (default: "
        "none, states from LOCAL_POSITION_NED)",
    )
    _add(
        p,
        "--local-origin",
        type=arg.triple,
        default=(0.0, 0.0, 0.0),
        metavar="X,Y,Z",
        help="world position (m, ENU) of the autopilots' local NED origin, without --origin "
        "(default 0,0,0: every vehicle's local frame is the scenario's, as with motion capture)",
    )
    _add(
        p,
        "--autopilot",
        choices=("auto", *AUTOPILOTS),
        default="auto",
        help="offboard (px4) or guided (ardupilot) control; auto: from the heartbeat (default)",
    )
    _add(
        p,
        "--system-ids",
        type=arg.system_ids,
        metavar="ID=SYSID,...",
        help="the MAVLink system id of each agent's autopilot (default: the k-th agent of the "
        "scenario is system k + 1); packets from other systems are ignored and counted",
    )
    _add(
        p,
        "--allow-system",
        type=arg.system_id,
        action="append",
        default=[],
        metavar="SYSID",
        help="another system whose ADSB_VEHICLE reports to take (a ground ADS-B receiver); "
        "repeatable",
    )
    _add(
        p,
        "--target-component",
        type=arg.component,
        default=1,
        metavar="N",
        help="the autopilot's component id (default 1, MAV_COMP_ID_AUTOPILOT1)",
    )
    _add(
        p,
        "--source-system",
        type=arg.system_id,
        metavar="N",
        help="the link's own system id (default: its autopilot's, as a companion computer)",
    )
    _add(
        p,
        "--source-component",
        type=arg.component,
        default=191,
        metavar="N",
        help="the link's own component id (default 191, MAV_COMP_ID_ONBOARD_COMPUTER)",
    )
    _add(
        p,
        "--arm",
        action="store_true",
        help="arm the vehicle before switching mode (default: it must be armed and flying)",
    )
    _add(p, "--baud", type=arg.baud, default=57600, help="serial baud rate (default 57600)")
    _add_timeouts(p)
    _add(
        p,
        "--traffic-r-pz",
        type=arg.positive,
        metavar="M",
        help="protected-zone radius of ADS-B traffic (default: the largest r_pz of the "
        "scenario's avoids: false agents, else of all)",
    )
    _add(
        p,
        "--traffic-speed",
        type=arg.positive,
        metavar="M/S",
        help="top speed of ADS-B traffic, for growing the zone of late reports (default: the "
        "fastest avoids: false agent's max_speed, else the scenario's)",
    )
    _add(
        p,
        "--time-scale",
        type=arg.time_scale,
        default=1.0,
        metavar="K",
        help="the link's clock runs K times real time, 0.001 to 1000 (vo3d sitl only; 1 on a "
        "real vehicle)",
    )
    _add(
        p,
        "--epoch",
        type=arg.epoch,
        metavar="T",
        help="the link's clock starts at this time.monotonic() reading (vo3d sitl only: one "
        "clock for every process; default: when the link starts)",
    )
    _add(p, "--log", metavar="FILE", help="write every tick to FILE (.npz), as vo3d sitl does")
    p.set_defaults(func=cmd_link)


def _add_timeouts(p: argparse.ArgumentParser) -> None:
    _add(
        p,
        "--prestream",
        type=arg.positive,
        default=1.0,
        metavar="S",
        help="seconds of zero set-points before asking for offboard/guided (default 1)",
    )
    _add(
        p,
        "--state-timeout",
        type=arg.positive,
        default=0.5,
        metavar="S",
        help="own state older than this: brake to a hover; a neighbour's: counted late "
        "(default 0.5)",
    )
    _add(
        p,
        "--link-timeout",
        type=arg.positive,
        default=3.0,
        metavar="S",
        help="no autopilot heartbeat for this long: link lost, brake to a hover (default 3)",
    )
    _add(
        p,
        "--neighbor-timeout",
        type=arg.positive,
        default=1.5,
        metavar="S",
        help="a neighbour silent for this long is dropped (default 1.5)",
    )
    _add(
        p,
        "--connect-timeout",
        type=arg.positive,
        default=30.0,
        metavar="S",
        help="give up when no autopilot heartbeat came within this (default 30)",
    )
    _add(
        p,
        "--mode-timeout",
        type=arg.positive,
        default=15.0,
        metavar="S",
        help="give up when the autopilot did not enter offboard/guided within this (default 15)",
    )
    _add(
        p,
        "--max-time",
        type=arg.positive,
        metavar="S",
        help="stop (brake and hold) this long after entering offboard/guided (default: the "
        "scenario's max_time)",
    )


def _add_sitl(sub: Any, parents: Sequence[argparse.ArgumentParser]) -> None:
    from vo3d_opt.link.faults import FAULT_HELP, parse_fault

    p = sub.add_parser(
        "sitl",
        parents=list(parents),
        help="fly a scenario as separate processes over MAVLink (test harness)",
        description=SITL_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add(p, "scenario", metavar="FILE", help="a scenario YAML file or a bundled name")
    _add(
        p,
        "--json",
        action="store_true",
        help="print the summary as one JSON object on stdout (default: a table)",
    )
    _add(p, "--out", metavar="DIR", help="also write what vo3d run --out writes to DIR")
    _add(
        p,
        "--rate",
        type=arg.rate,
        default=10.0,
        metavar="HZ",
        help="each link's decisions per second, 0.01 to 1000 (default 10)",
    )
    _add(
        p,
        "--time-scale",
        type=arg.time_scale,
        default=1.0,
        metavar="K",
        help="run K times faster than real time, 0.001 to 1000 (default 1)",
    )
    _add(
        p,
        "--autopilot",
        choices=AUTOPILOTS,
        default="px4",
        help="which autopilot the simulated vehicles behave as (default px4)",
    )
    _add(p, "--signing-key", metavar="FILE", help="sign every packet with this key (all sides)")
    _add(
        p,
        "--origin",
        type=arg.origin,
        default=parse_origin(SITL_ORIGIN),
        metavar="LAT,LON,ALT",
        help=f"geodetic position of the world's origin (default {SITL_ORIGIN})",
    )
    _add(
        p,
        "--physics-rate",
        type=arg.sim_rate,
        default=50.0,
        metavar="HZ",
        help="dynamics steps per second of each vehicle, 0.01 to 10000 (default 50)",
    )
    _add(
        p,
        "--telemetry-rate",
        type=arg.sim_rate,
        default=25.0,
        metavar="HZ",
        help="state messages per second of each vehicle, 0.01 to 10000 (default 25)",
    )
    _add(
        p,
        "--setpoint-timeout",
        type=arg.positive,
        default=0.5,
        metavar="S",
        help="a vehicle without set-points this long holds (default 0.5)",
    )
    _add(
        p, "--fault", type=parse_fault, action="append", default=[], metavar="SPEC", help=FAULT_HELP
    )
    p.set_defaults(func=cmd_sitl)


def add_parsers(sub: Any, parents: Sequence[argparse.ArgumentParser]) -> None:
    """Add ``link`` and ``sitl`` to ``vo3d``'s subparsers (``parents``: the common options)."""
    _add_link(sub, parents)
    _add_sitl(sub, parents)


def link_main(argv: Sequence[str]) -> int:
    """``vo3d link ARGV``'s status, in this process: what a forked link of ``vo3d sitl`` runs
    (``-q`` / ``-v`` as ``vo3d`` takes them)."""
    from vo3d_opt.console import configure_logging

    noise = argparse.ArgumentParser(add_help=False)
    noise.add_argument("-q", dest="verbosity", action="store_const", const=-1, default=0)
    noise.add_argument("-v", dest="verbosity", action="store_const", const=1)
    parser = argparse.ArgumentParser(prog="vo3d")
    _add_link(parser.add_subparsers(dest="command", required=True), [noise])
    args = parser.parse_args(list(argv))
    configure_logging(args.verbosity)
    return int(args.func(args))


def _usage(message: str) -> int:
    log.error("%s", " ".join(message.split()))
    return EXIT_USAGE


def _guarded(run: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """``run`` with a missing extra and bad files turned into exit status 2, one line."""

    def wrapped(args: argparse.Namespace) -> int:
        try:
            check("link", f"vo3d {args.command}")
            return run(args)
        except MissingExtra as exc:
            return _usage(str(exc))
        except _Usage as exc:
            return _usage(str(exc))

    return wrapped


class _Usage(Exception):
    """Bad input, reported as one line and exit status 2."""


def _scenario(arg: str, flag: str) -> Any:
    from vo3d_opt.sim.scenario import ScenarioError, load_scenario

    try:
        return load_scenario(arg)
    except ScenarioError as exc:
        raise _Usage(f"{flag}: {exc}") from None


def _key(path: str | None) -> bytes | None:
    from vo3d_opt.link.messages import load_signing_key

    if path is None:
        return None
    try:
        return load_signing_key(path)
    except ValueError as exc:
        raise _Usage(f"--signing-key {exc}") from None


def link_options(args: argparse.Namespace) -> Any:
    """:class:`~vo3d_opt.link.loop.LinkOptions` from ``vo3d link``'s arguments."""
    from vo3d_opt.link.loop import LinkOptions

    sc = _scenario(args.scenario, "--scenario")
    if args.agent not in sc.ids:
        raise _Usage(f"--agent {args.agent!r}: not in {sc.name} ({', '.join(sc.ids)})")
    ids = args.system_ids or {name: k + 1 for k, name in enumerate(sc.ids)}
    if args.agent not in ids:
        raise _Usage(f"--system-ids: no system id for --agent {args.agent}")
    unknown = sorted(set(ids) - set(sc.ids))
    if unknown:
        raise _Usage(f"--system-ids: {', '.join(unknown)} not in {sc.name}")
    return LinkOptions(
        connect=args.connect,
        scenario=sc,
        agent=args.agent,
        system_ids=ids,
        rate=args.rate,
        signing_key=_key(args.signing_key),
        origin=args.origin,
        local_origin=args.local_origin,
        autopilot=args.autopilot,
        target_component=args.target_component,
        source_system=args.source_system,
        source_component=args.source_component,
        extra_systems=tuple(args.allow_system),
        arm=args.arm,
        prestream=args.prestream,
        state_timeout=args.state_timeout,
        link_timeout=args.link_timeout,
        neighbor_timeout=args.neighbor_timeout,
        connect_timeout=args.connect_timeout,
        mode_timeout=args.mode_timeout,
        max_time=args.max_time if args.max_time is not None else float(sc.max_time),
        traffic_r_pz=args.traffic_r_pz,
        traffic_speed=args.traffic_speed,
        time_scale=args.time_scale,
        epoch=args.epoch,
        baud=args.baud,
        log_file=_log_file(args.log) if args.log else None,
    )


def _log_file(arg: str) -> Path:
    """The ``--log`` file, its directory tried now: a log that cannot be written fails
    before the flight, not after it."""
    path = Path(arg)
    if path.is_dir():
        raise _Usage(f"--log {arg}: is a directory")
    try:
        with tempfile.TemporaryFile(dir=path.parent):
            pass
    except OSError as exc:
        raise _Usage(f"--log {arg}: cannot write there: {exc.strerror or exc}") from None
    return path


@_guarded
def cmd_link(args: argparse.Namespace) -> int:
    from vo3d_opt.link.loop import Link

    opts = link_options(args)
    try:
        link = Link(opts)
    except (OSError, ValueError, ImportError) as exc:  # a connection that cannot be opened
        raise _Usage(f"--connect {args.connect}: {exc}") from None
    link.run(report=_print_summary)
    return 1 if link.log_failed else 0


def _print_summary(summary: dict[str, Any]) -> None:
    print(json.dumps(summary, allow_nan=False, default=_plain))
    sys.stdout.flush()


def _plain(value: Any) -> Any:
    return value.item() if hasattr(value, "item") else str(value)


@_guarded
def cmd_sitl(args: argparse.Namespace) -> int:
    from vo3d_opt.link.sitl import SitlOptions, print_sitl_summary, run_sitl

    sc = _scenario(args.scenario, "FILE")
    _key(args.signing_key)
    out = _out_dir(args.out) if args.out else None
    opts = SitlOptions(
        scenario=sc,
        rate=args.rate,
        time_scale=args.time_scale,
        autopilot=args.autopilot,
        signing_key=args.signing_key,
        origin=args.origin,
        physics_rate=args.physics_rate,
        telemetry_rate=args.telemetry_rate,
        setpoint_timeout=args.setpoint_timeout,
        faults=list(args.fault),
        link_main=link_main,
    )
    try:
        result = run_sitl(opts)
    except ValueError as exc:
        raise _Usage(str(exc)) from None
    except RuntimeError as exc:
        log.error("vo3d sitl: %s", exc)
        return 1
    status = 130 if result.interrupted else 0
    if out is not None:
        status = max(status, result.write(out))
    if args.json:
        print(json.dumps(result.summary, allow_nan=False, default=_plain))
    else:
        print_sitl_summary(result.summary)
    return status


def _out_dir(arg: str) -> Path:
    path = Path(arg)
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".vo3d-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise _Usage(f"--out {arg}: cannot write there: {exc.strerror or exc}") from None
    return path
