"""The MAVLink link's parts: frames against known points and PROJ, messages against
pymavlink's own definitions, rejected packets over a real UDP socket, the neighbour table's
rules, the selector and planning world against the simulator's, and the command line's errors."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pymavlink")
pyproj = pytest.importorskip("pyproj")

from vo3d_opt.link.faults import Fault, Injector, parse_fault  # noqa: E402
from vo3d_opt.link.frames import GeodeticFrame, enu_to_ned, ned_to_enu, parse_origin  # noqa: E402
from vo3d_opt.link.messages import (  # noqa: E402
    Rejected, adsb_vehicle, global_position, load_signing_key, local_position, mavlink,
    read_state, setpoint, setpoint_velocity, under_external_control, px4_custom_mode,
)
from vo3d_opt.link.neighbors import JUMP_SLACK, Track, Tracks  # noqa: E402
from vo3d_opt.link.planning import Plan, link_selector  # noqa: E402
from vo3d_opt.link.transport import MavlinkPort  # noqa: E402
from vo3d_opt.sim.deciders import PerAgentSelect  # noqa: E402
from vo3d_opt.sim.scenario import load_scenario  # noqa: E402
from vo3d_opt.sim.simulator import Snapshot, scenario_selector  # noqa: E402
from vo3d_opt.types import AgentState  # noqa: E402

DATA = Path(__file__).parent / "data"
ZURICH = (47.397742, 8.545594, 488.0)


# --- frames ------------------------------------------------------------------------------------

def test_ned_and_enu_swap_the_horizontal_axes_and_flip_the_vertical():
    assert np.allclose(ned_to_enu((1.0, 2.0, 3.0)), (2.0, 1.0, -3.0))  # north 1, east 2, down 3
    assert np.allclose(enu_to_ned((2.0, 1.0, -3.0)), (1.0, 2.0, 3.0))
    many = np.random.default_rng(0).normal(size=(50, 3))
    assert np.allclose(enu_to_ned(ned_to_enu(many)), many)


def test_geodetic_frame_against_known_points_and_pyproj_geodesics():
    frame = GeodeticFrame(0.0, 0.0, 0.0)
    assert np.allclose(frame.to_world(0.0, 0.0, 0.0), 0.0, atol=1e-9)
    # 0.001 degree of latitude at the equator: 110.574 m of meridian (WGS 84)
    north = frame.to_world(0.001, 0.0, 0.0)
    assert north[1] == pytest.approx(110.574, abs=1e-3) and abs(north[0]) < 1e-6
    # straight up: the up axis
    assert np.allclose(frame.to_world(0.0, 0.0, 100.0), (0.0, 0.0, 100.0), atol=1e-6)
    # away from the equator, a point 300 m off at 60 degrees bearing on the ellipsoid: the
    # plane's distance is the geodesic's to a millimetre, and the bearing its azimuth (488 m
    # above the ellipsoid the same angles span 300 (1 + 488 / 6.38e6) = 300.023 m)
    z = GeodeticFrame(ZURICH[0], ZURICH[1], 0.0)
    geod = pyproj.Geod(ellps="WGS84")
    lon, lat, _ = geod.fwd(ZURICH[1], ZURICH[0], 60.0, 300.0)
    p = z.to_world(lat, lon, 0.0)
    assert np.hypot(p[0], p[1]) == pytest.approx(300.0, abs=1e-3)
    high = GeodeticFrame(*ZURICH).to_world(lat, lon, ZURICH[2])
    assert np.hypot(high[0], high[1]) == pytest.approx(300.023, abs=1e-3)
    assert np.degrees(np.arctan2(p[0], p[1])) == pytest.approx(60.0, abs=1e-3)
    assert abs(p[2]) < 0.01  # the earth curves 7 mm away over 300 m


def test_geodetic_round_trips():
    z = GeodeticFrame(*ZURICH)
    pts = np.random.default_rng(1).uniform((-500, -500, 0), (500, 500, 120), size=(100, 3))
    back = z.to_world(*z.to_geodetic(pts).T)
    assert np.max(np.abs(back - pts)) < 1e-6
    one = z.to_geodetic((10.0, 20.0, 30.0))
    assert one.shape == (3,) and np.allclose(z.to_world(*one), (10.0, 20.0, 30.0), atol=1e-6)


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "91,0,0", "0,181,0", "nan,0,0"])
def test_bad_origins_are_refused(text):
    with pytest.raises(ValueError):
        parse_origin(text)


# --- messages ----------------------------------------------------------------------------------

def _decode(msg, mav):
    """Pack with ``mav`` and parse with a fresh pymavlink parser."""
    other = mavlink().MAVLink(None)
    return other.parse_char(msg.pack(mav))


def test_setpoint_is_velocity_only_in_local_ned_by_pymavlinks_definitions():
    m = mavlink()
    mav = m.MAVLink(None, srcSystem=3, srcComponent=191)
    out = _decode(setpoint(mav, (1.0, 2.0, 0.5), time_boot_ms=1234, target_system=3,
                           target_component=1), mav)
    assert out.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert out.coordinate_frame == m.MAV_FRAME_LOCAL_NED
    ignored = [m.POSITION_TARGET_TYPEMASK_X_IGNORE, m.POSITION_TARGET_TYPEMASK_Y_IGNORE,
               m.POSITION_TARGET_TYPEMASK_Z_IGNORE, m.POSITION_TARGET_TYPEMASK_AX_IGNORE,
               m.POSITION_TARGET_TYPEMASK_AY_IGNORE, m.POSITION_TARGET_TYPEMASK_AZ_IGNORE,
               m.POSITION_TARGET_TYPEMASK_YAW_IGNORE, m.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE]
    used = [m.POSITION_TARGET_TYPEMASK_VX_IGNORE, m.POSITION_TARGET_TYPEMASK_VY_IGNORE,
            m.POSITION_TARGET_TYPEMASK_VZ_IGNORE, m.POSITION_TARGET_TYPEMASK_FORCE_SET]
    assert all(out.type_mask & bit for bit in ignored)
    assert not any(out.type_mask & bit for bit in used)
    assert out.type_mask == 0b110111000111  # 3527: what PX4 and ArduPilot document
    assert (out.vx, out.vy, out.vz) == pytest.approx((2.0, 1.0, -0.5))  # north, east, down
    assert (out.target_system, out.target_component) == (3, 1)
    assert setpoint_velocity(out) == pytest.approx((1.0, 2.0, 0.5))
    out.type_mask = 0  # a position set-point: not what the vehicle flies
    assert setpoint_velocity(out) is None


def test_px4_and_ardupilot_modes():
    assert px4_custom_mode(6) == 6 << 16 and under_external_control("px4", 6 << 16)
    assert not under_external_control("px4", px4_custom_mode(4, 3))  # hold (auto loiter)
    assert under_external_control("ardupilot", 4) and not under_external_control("ardupilot", 5)


def test_states_read_back_in_the_world_frame():
    m = mavlink()
    mav = m.MAVLink(None, srcSystem=5, srcComponent=1)
    frame = GeodeticFrame(*ZURICH)
    p, v = np.array([12.3, -45.6, 20.7]), np.array([1.5, -2.25, 0.5])
    glob = read_state(_decode(global_position(mav, frame, p, v, 100), mav), frame, np.zeros(3))
    assert glob.source == 5 and glob.kind == "GLOBAL_POSITION_INT"
    assert np.max(np.abs(glob.position - p)) < 0.02  # 1e-7 degree and mm quantisation
    assert np.allclose(glob.velocity, v, atol=0.006)
    local = read_state(_decode(local_position(mav, p, v, 100), mav), None, np.array([1.0, 2, 3]))
    assert np.allclose(local.position, p + (1, 2, 3), atol=1e-4)
    assert np.allclose(local.velocity, v, atol=1e-6)
    adsb = read_state(_decode(adsb_vehicle(mav, frame, p, v, 0xABCDEF), mav), frame, np.zeros(3))
    assert adsb.icao == 0xABCDEF and np.max(np.abs(adsb.position - p)) < 0.02
    assert np.allclose(adsb.velocity, v, atol=0.01)


def test_non_finite_and_impossible_states_are_rejected_with_a_reason():
    m = mavlink()
    mav = m.MAVLink(None, srcSystem=5, srcComponent=1)
    frame = GeodeticFrame(*ZURICH)
    bad = _decode(mav.local_position_ned_encode(0, float("nan"), 0.0, 0.0, 0.0, 0.0, 0.0), mav)
    with pytest.raises(Rejected) as err:
        read_state(bad, None, np.zeros(3))
    assert err.value.reason == "non_finite"
    far = global_position(mav, frame, np.zeros(3), np.zeros(3), 0)
    far.lat = 95 * 10_000_000
    with pytest.raises(Rejected) as err:
        read_state(_decode(far, mav), frame, np.zeros(3))
    assert err.value.reason == "impossible"
    with pytest.raises(Rejected) as err:  # geodetic without an origin
        read_state(_decode(global_position(mav, frame, np.zeros(3), np.zeros(3), 0), mav),
                   None, np.zeros(3))
    assert err.value.reason == "no_origin"


def test_signing_keys(tmp_path):
    raw, hexed, bad = tmp_path / "raw", tmp_path / "hex", tmp_path / "bad"
    raw.write_bytes(bytes(range(32)))
    hexed.write_text(bytes(range(32)).hex() + "\n")
    bad.write_text("secret")
    assert load_signing_key(raw) == load_signing_key(hexed) == bytes(range(32))
    with pytest.raises(ValueError, match="bad"):
        load_signing_key(bad)
    with pytest.raises(ValueError, match="missing"):
        load_signing_key(tmp_path / "missing")


# --- rejected packets over a real socket -------------------------------------------------------

def _port(key: bytes | None) -> tuple[MavlinkPort, int]:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        number = s.getsockname()[1]
    return MavlinkPort(f"udpin:127.0.0.1:{number}", source_system=9, source_component=191,
                       signing_key=key), number


def _drain(port: MavlinkPort, expect: int) -> list:
    got, deadline = [], time.monotonic() + 5.0
    while time.monotonic() < deadline:
        port.wait(0.05)
        got += port.receive()
        if len(got) + sum(port.rejected.values()) >= expect:
            break
    return got


@pytest.mark.parametrize("signed", [False, True])
def test_every_rejected_packet_is_counted_by_reason(signed):
    key = bytes(range(1, 33)) if signed else None
    port, number = _port(key)
    injector = Injector(number, {"a": 4}, GeodeticFrame(*ZURICH), key)
    sent = 0
    for spec in ["garbage:0:7", "malformed:0:3", "unsigned:0:4", "badsig:0:5", "foreign:0:2"]:
        sent += injector.send(parse_fault(spec))
    good = Injector(number, {"a": 4}, GeodeticFrame(*ZURICH), key)
    sent += good.send(Fault(kind="foreign", at=0.0, amount=1))  # one well-formed packet
    got = _drain(port, sent - (0 if signed else 9) - 3)
    r = port.rejected
    port.close()
    assert r["bad_prefix"] == 7 and r["bad_crc"] == 3 and r["truncated"] == 3
    if signed:
        assert r["unsigned"] == 4 and r["bad_signature"] == 5
    else:  # unsigned and wrongly signed packets are good packets when no key is set
        assert "unsigned" not in r and "bad_signature" not in r
    # what parsed: the impossible states (refused later, by the link), the foreign reports
    kinds = [m.get_type() for m in got]
    assert kinds.count("GLOBAL_POSITION_INT") == 3 + 3 + (0 if signed else 9)


def _closing_server() -> tuple[socket.socket, int]:
    """A TCP listener on 127.0.0.1 (and its port) that will close the connection it accepts."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    return srv, srv.getsockname()[1]


@pytest.mark.parametrize("reset", [False, True])
def test_a_tcp_connection_closed_by_the_autopilot_is_seen_as_closed(capfd, reset):
    import struct

    srv, number = _closing_server()
    port = MavlinkPort(f"tcp:127.0.0.1:{number}", source_system=1, source_component=191)
    conn, _ = srv.accept()
    if reset:  # closed with a RST, not a FIN: pymavlink's recv raises
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    conn.close()
    for _ in range(50):
        port.wait(0.1)
        assert port.receive() == []
        if port.closed:
            break
    closed = port.closed
    port.close()
    srv.close()
    assert closed and capfd.readouterr().out == ""


def test_a_listening_tcp_connection_whose_peer_closes_is_seen_as_closed(capfd):
    """``tcpin:``: once the autopilot that connected closes, the socket reads as ready for
    ever; the port calls it closed instead of spinning."""
    srv, number = _closing_server()
    srv.close()  # a free port for the link to listen on
    port = MavlinkPort(f"tcpin:127.0.0.1:{number}", source_system=1, source_component=191)
    peer = socket.create_connection(("127.0.0.1", number))
    calls = 0
    for calls in range(1, 201):
        port.wait(0.05)
        assert port.receive() == []
        if calls == 2:
            peer.close()
        if port.closed:
            break
    closed = port.closed
    port.close()
    assert closed and calls < 200 and capfd.readouterr().out == ""


def test_a_refused_tcp_connection_is_one_line_on_stderr_and_nothing_on_stdout(capsys):
    srv, number = _closing_server()
    srv.close()  # nothing listens there now
    code, out, err = _vo3d(capsys, "link", "--connect", f"tcp:127.0.0.1:{number}", "--scenario",
                           str(DATA / "link-three.yaml"), "--agent", "a0")
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1 and "--connect tcp:" in lines[0], err


def test_link_ends_when_its_tcp_connection_closes(capsys):
    import threading

    srv, number = _closing_server()
    threading.Thread(target=lambda: srv.accept()[0].close(), daemon=True).start()
    code, out, _ = _vo3d(capsys, "link", "--connect", f"tcp:127.0.0.1:{number}", "--scenario",
                         str(DATA / "link-three.yaml"), "--agent", "a0", "--connect-timeout", "5")
    srv.close()
    assert code == 0 and len(out.splitlines()) == 1
    assert json.loads(out)["end"] == "connection closed"


# --- neighbour table ---------------------------------------------------------------------------

def _tracks() -> Tracks:
    t = Tracks(timeout=1.5, late_after=0.5, sensing_range=40.0, own_r_pz=5.0)
    t.add_peer(2, "b", r_pz=6.0, top_speed=4.0)
    return t


def test_late_neighbours_grow_by_age_times_top_speed_then_drop():
    t = _tracks()
    peer = t.peers[2]
    assert t.update(peer, np.array([10.0, 0, 20]), np.zeros(3), now=0.0) is None
    t.heartbeat(2, True, 0.0)
    (n,) = t.neighbors(np.array([0.0, 0, 20]), now=0.25)
    assert n.r_pz == pytest.approx(6.0 + 0.25 * 4.0) and n.cooperative
    (n,) = t.neighbors(np.array([0.0, 0, 20]), now=1.0)
    assert n.r_pz == pytest.approx(6.0 + 4.0) and t.late["b"] == 1
    assert t.neighbors(np.array([0.0, 0, 20]), now=1.6) == [] and t.drops["b"] == 1
    # a dropped track is taken afresh from anywhere
    assert t.update(peer, np.array([30.0, 0, 20]), np.zeros(3), now=2.0) is None
    assert len(t.neighbors(np.array([0.0, 0, 20]), now=2.0)) == 1


def test_implausible_reports_are_refused():
    t = _tracks()
    peer = t.peers[2]
    t.update(peer, np.array([10.0, 0, 20]), np.zeros(3), now=0.0)
    reach = (2 * 4.0 + 2.0) * 0.1 + JUMP_SLACK
    assert t.update(peer, np.array([10.0 + reach + 0.1, 0, 20]), np.zeros(3), 0.1) == \
        "implausible_jump"
    assert t.update(peer, np.array([10.0 + reach - 0.1, 0, 20]), np.zeros(3), 0.1) is None
    assert t.update(peer, np.array([12.0, 0, 20]), np.array([11.0, 0, 0]), 0.2) == "impossible"


def test_cooperative_only_under_external_control_and_with_a_recent_heartbeat():
    t = _tracks()
    t.update(t.peers[2], np.array([10.0, 0, 20]), np.zeros(3), now=0.0)
    assert not t.neighbors(np.zeros(3) + (0, 0, 20), 0.0)[0].cooperative  # no heartbeat yet
    t.heartbeat(2, False, 0.0)
    assert not t.neighbors(np.zeros(3) + (0, 0, 20), 0.0)[0].cooperative  # holding
    t.heartbeat(2, True, 0.0)
    t.update(t.peers[2], np.array([10.0, 0, 20]), np.zeros(3), now=3.5)
    assert not t.neighbors(np.zeros(3) + (0, 0, 20), 3.5)[0].cooperative  # heartbeat too old
    assert t.passive["b"] == 3
    assert t.neighbors(np.array([100.0, 0, 20]), 3.5) == []  # out of sensing range


def test_track_refuses_a_speed_beyond_the_cap_even_when_fresh():
    track = Track("x", 5.0, 4.0)
    assert track.plausible(np.zeros(3), np.array([0.0, 0, 10.1]), 0.0, 1.5) == "impossible"


# --- the selector and what it plans with -------------------------------------------------------

def test_the_link_flies_the_default_preset():
    """A link's selector is ``VelocitySelector()``'s configuration (the ``safe`` preset), told
    the scenario's sensing range."""
    from vo3d_opt import VelocitySelector

    sc = load_scenario(DATA / "link-crossing.yaml")
    built = link_selector(sc, "a1").selector.config
    default = VelocitySelector(sensing_range=sc.sensing.vehicle_range).config
    assert built == default and built.preset == "safe"


def test_link_decides_what_the_simulator_decides_on_the_same_snapshot():
    sc = load_scenario(DATA / "link-crossing.yaml")
    built = link_selector(sc, "a1")
    sim_sel, formulation, solver = scenario_selector(sc)
    assert (built.formulation, built.solver) == (formulation, solver)
    rng = np.random.default_rng(3)
    p = sc.starts * 0.5 + rng.normal(scale=0.5, size=sc.starts.shape)
    v = rng.normal(scale=1.0, size=p.shape)
    plan = Plan(sc, "a1", float(sc.dt))
    w = np.array([plan.preferred(p[1]) if i == 1 else np.zeros(3) for i in range(sc.n_agents)])
    deciding = np.array([True] * 4 + [False])
    snap = Snapshot(k=0, t=0.0, positions=p, velocities=v, preferred=w, deciding=deciding)
    ref = PerAgentSelect(sc, sim_sel).decide(snap).commands[1]
    tracks = Tracks(timeout=1.5, late_after=0.5, sensing_range=40.0, own_r_pz=5.0,
                    traffic_r_pz=float(sc.r_pz[4]), traffic_speed=4.0)
    for k in (0, 2, 3):  # the peers, cooperative, then the intruder as ADS-B traffic
        tracks.add_peer(k + 1, sc.ids[k], float(sc.r_pz[k]), 4.0)
        tracks.update(tracks.peers[k + 1], p[k], v[k], now=0.0)
        tracks.heartbeat(k + 1, True, 0.0)
    tracks.update(tracks.track_for(9, 0xAB), p[4], v[4], now=0.0)
    d = built.selector.select(own=AgentState(position=p[1], velocity=v[1]),
                              preferred_velocity=w[1], neighbors=tracks.neighbors(p[1], 0.0),
                              obstacles=plan.obstacles(p[1]), limits=plan.limits, dt=sc.dt)
    assert np.allclose(d.velocity, ref, atol=1e-9)


# --- the command line --------------------------------------------------------------------------

def _vo3d(capsys, *args: str) -> tuple[int, str, str]:
    """``vo3d ARGS`` in this process: (status, stdout, stderr)."""
    from vo3d_opt.cli import main

    try:
        code = main(list(args))
    except SystemExit as exc:  # argparse
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("args, named", [
    (["--origin", "91,0,0"], "--origin"),
    (["--agent", "nobody"], "--agent"),
    (["--rate", "0"], "--rate"),
    (["--system-ids", "a0=1,a1=1"], "--system-ids"),
    (["--signing-key", "/no/such/key"], "--signing-key"),
    (["--scenario", "/no/such.yaml"], "--scenario"),
    (["--connect", "/dev/no-such-serial-port"], "--connect"),
    (["--log", "/no/such/dir/link.npz", "--connect-timeout", "0.2"], "--log"),
])
def test_link_bad_arguments_exit_2_with_one_line_naming_them(capsys, args, named):
    base = {"--connect": "udpin:127.0.0.1:0", "--scenario": str(DATA / "link-three.yaml"),
            "--agent": "a0"}
    for flag, value in zip(args[::2], args[1::2], strict=True):
        base[flag] = value
    code, out, err = _vo3d(capsys, "link", *[x for kv in base.items() for x in kv])
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and named in lines[0], err


def test_a_log_that_cannot_be_written_still_prints_the_summary(monkeypatch, capsys, tmp_path):
    from vo3d_opt.link.report import LinkLog

    def full(self, path):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(LinkLog, "save", full)
    code, out, err = _vo3d(capsys, "link", "--connect", "udpin:127.0.0.1:0", "--scenario",
                           str(DATA / "link-three.yaml"), "--agent", "a0", "--connect-timeout",
                           "0.2", "--log", str(tmp_path / "link.npz"))
    assert code == 1 and json.loads(out)["end"] == "no autopilot heartbeat"
    assert "--log" in err and "No space left on device" in err


def test_a_second_ctrl_c_while_stopping_still_ends_with_the_summary(monkeypatch, capsys, tmp_path):
    import signal

    from vo3d_opt.link.report import LinkLog

    def interrupted(self, path):  # Ctrl-C again while the link brakes, asks for hold, saves
        os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(LinkLog, "save", interrupted)
    code, out, _ = _vo3d(capsys, "link", "--connect", "udpin:127.0.0.1:0", "--scenario",
                         str(DATA / "link-three.yaml"), "--agent", "a0", "--connect-timeout",
                         "0.2", "--log", str(tmp_path / "link.npz"))
    assert code == 0 and json.loads(out)["end"] == "no autopilot heartbeat"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def _parse_error(capsys, *argv: str) -> tuple[int | None, list[str]]:
    """Parse ``vo3d ARGV`` only (nothing is opened or flown): (exit status, stderr lines)."""
    from vo3d_opt.cli.app import build_vo3d_parser

    try:
        build_vo3d_parser().parse_args(list(argv))
    except SystemExit as exc:
        return int(exc.code or 0), capsys.readouterr().err.strip().splitlines()
    return None, []


LINK_ARGS = ("link", "--connect", "udpin:127.0.0.1:0", "--scenario", "x.yaml", "--agent", "a0")


@pytest.mark.parametrize("flag, value", [
    ("--epoch", "nan"),  # a NaN clock never times out: the link would wait for ever
    ("--epoch", "inf"),
    ("--epoch", "1e300"),  # finite, but monotonic() - epoch no longer moves
    ("--rate", "1e-300"),  # a period beyond what select() can wait
    ("--rate", "1e300"),
    ("--time-scale", "1e-300"),
    ("--time-scale", "1e300"),
    ("--baud", "-5"),
    ("--baud", "0"),
])
def test_link_timing_arguments_out_of_range_exit_2_naming_them(capsys, flag, value):
    code, err = _parse_error(capsys, *LINK_ARGS, flag, value)
    assert code == 2 and len(err) == 1 and flag in err[0], err


@pytest.mark.parametrize("flag, value", [
    ("--rate", "1e-300"), ("--time-scale", "1e-300"), ("--physics-rate", "1e-300"),
    ("--physics-rate", "1e300"), ("--telemetry-rate", "1e-300"),
])
def test_sitl_timing_arguments_out_of_range_exit_2_naming_them(capsys, flag, value):
    code, err = _parse_error(capsys, "sitl", "x.yaml", flag, value)
    assert code == 2 and len(err) == 1 and flag in err[0], err


def test_sitl_bad_arguments_exit_2_with_one_line(capsys, tmp_path):
    for args, named in [(["/no/such.yaml"], "FILE"),
                        ([str(DATA / "link-three.yaml"), "--fault", "kill:zz:1"], "zz"),
                        ([str(DATA / "link-three.yaml"), "--fault", "boom:1"], "--fault")]:
        code, out, err = _vo3d(capsys, "sitl", *args)
        lines = err.strip().splitlines()
        assert code == 2 and out == "" and len(lines) == 1 and named in lines[0], err


def test_link_help_says_how_to_connect_to_a_real_autopilot(capsys):
    code, out, _ = _vo3d(capsys, "link", "--help")
    assert code == 0
    for what in ("udpin:0.0.0.0:14540", "COM_OF_LOSS_T", "GUID_TIMEOUT", "MAV_SYS_ID",
                 "--signing-key", "/dev/ttyACM0"):
        assert what in out


def test_import_vo3d_opt_does_not_import_the_link_extra():
    code = "import sys, vo3d_opt, vo3d_opt.cli; print(json.dumps(sorted(m for m in sys.modules " \
           "if m.split('.')[0] in ('pymavlink', 'pyproj'))))"
    res = subprocess.run([sys.executable, "-c", "import json; " + code], capture_output=True,
                         text=True, timeout=60)
    assert json.loads(res.stdout) == []


def test_a_missing_extra_is_one_line_naming_it(monkeypatch, capsys):
    import importlib.util

    from vo3d_opt.cli import main

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "pymavlink" else real(name, *a))
    code = main(["link", "--connect", "udpin:127.0.0.1:0", "--scenario",
                 str(DATA / "link-three.yaml"), "--agent", "a0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "[link]" in err[0] and "pymavlink" in err[0]
