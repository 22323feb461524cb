"""The MAVLink messages the link and the simulated vehicles exchange, on pymavlink.

pymavlink is imported on first use (:func:`mavlink`), with MAVLink 2 chosen (``MAVLINK20``,
needed for signing) unless the environment already chose: ``import vo3d_opt`` never imports
it. The message definitions are pymavlink's own; this module only fills and reads them:

* set-points: ``SET_POSITION_TARGET_LOCAL_NED`` in ``MAV_FRAME_LOCAL_NED`` with
  :data:`velocity_only_mask` (position, acceleration, yaw and yaw rate ignored): what PX4's
  offboard mode and ArduPilot's guided mode both take as a velocity command;
* modes: PX4 encodes its modes as ``custom_mode = main << 16 | sub << 24`` (offboard: main 6;
  hold: auto 4 / loiter 3), set with ``MAV_CMD_DO_SET_MODE`` (param1
  ``MAV_MODE_FLAG_CUSTOM_MODE_ENABLED``, param2 main, param3 sub); ArduCopter numbers its
  modes (guided 4, loiter 5), set with the same command (param2 the number);
* states: ``LOCAL_POSITION_NED``, ``GLOBAL_POSITION_INT`` and ``ADSB_VEHICLE`` read into
  :class:`StateReport` (world ENU, SI units), rejected with a reason when not finite or
  impossible.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.link.frames import GeodeticFrame, enu_to_ned, ned_to_enu

#: The companion computer's component id (MAV_COMP_ID_ONBOARD_COMPUTER) and the autopilot's.
ONBOARD_COMPONENT = 191
AUTOPILOT_COMPONENT = 1
#: PX4's custom main modes and the auto sub-mode "loiter" (px4_custom_mode.h).
PX4_MAIN_AUTO, PX4_MAIN_OFFBOARD, PX4_SUB_LOITER = 4, 6, 3
#: ArduCopter's mode numbers.
APM_GUIDED, APM_LOITER = 4, 5
AUTOPILOTS = ("px4", "ardupilot")
#: Latitudes and longitudes arrive in 1e-7 degrees, altitudes in mm, speeds in cm/s.
DEG_E7, MM, CM = 1e-7, 1e-3, 1e-2


def mavlink() -> ModuleType:
    """pymavlink's generated dialect module (MAVLink 2)."""
    os.environ.setdefault("MAVLINK20", "1")
    with needs("link", "MAVLink"):
        from pymavlink import mavutil

    return mavutil.mavlink


def velocity_only_mask() -> int:
    """``type_mask`` of a velocity-only set-point: every ignore bit but the velocity ones."""
    m = mavlink()
    return int(
        m.POSITION_TARGET_TYPEMASK_X_IGNORE
        | m.POSITION_TARGET_TYPEMASK_Y_IGNORE
        | m.POSITION_TARGET_TYPEMASK_Z_IGNORE
        | m.POSITION_TARGET_TYPEMASK_AX_IGNORE
        | m.POSITION_TARGET_TYPEMASK_AY_IGNORE
        | m.POSITION_TARGET_TYPEMASK_AZ_IGNORE
        | m.POSITION_TARGET_TYPEMASK_YAW_IGNORE
        | m.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
    )


def setpoint(
    mav: Any, velocity_enu: Any, *, time_boot_ms: int, target_system: int, target_component: int
) -> Any:
    """A velocity-only ``SET_POSITION_TARGET_LOCAL_NED`` (world ENU velocity in, NED out)."""
    m = mavlink()
    vn, ve, vd = (float(c) for c in enu_to_ned(velocity_enu))
    return mav.set_position_target_local_ned_encode(
        int(time_boot_ms) & 0xFFFFFFFF,
        target_system,
        target_component,
        m.MAV_FRAME_LOCAL_NED,
        velocity_only_mask(),
        0.0,
        0.0,
        0.0,
        vn,
        ve,
        vd,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    )


def setpoint_velocity(msg: Any) -> np.ndarray | None:
    """The world ENU velocity of a velocity-only local-NED set-point; None for any other
    (another frame or mask: what the simulated vehicle refuses)."""
    m = mavlink()
    if msg.coordinate_frame != m.MAV_FRAME_LOCAL_NED or msg.type_mask != velocity_only_mask():
        return None
    v = ned_to_enu((msg.vx, msg.vy, msg.vz))
    return v if np.all(np.isfinite(v)) else None


# --- modes -------------------------------------------------------------------------------------


def px4_custom_mode(main: int, sub: int = 0) -> int:
    return (main << 16) | (sub << 24)


def external_mode(autopilot: str) -> tuple[int, int]:
    """(param2, param3) of ``MAV_CMD_DO_SET_MODE`` for offboard (PX4) / guided (ArduPilot)."""
    return (PX4_MAIN_OFFBOARD, 0) if autopilot == "px4" else (APM_GUIDED, 0)


def hold_mode(autopilot: str) -> tuple[int, int]:
    """(param2, param3) for PX4's hold (auto loiter) / ArduCopter's loiter."""
    return (PX4_MAIN_AUTO, PX4_SUB_LOITER) if autopilot == "px4" else (APM_LOITER, 0)


def custom_mode_of(autopilot: str, main: int, sub: int) -> int:
    """The heartbeat's ``custom_mode`` for a mode set with (param2, param3)."""
    return px4_custom_mode(main, sub) if autopilot == "px4" else main


def flavour(heartbeat_autopilot: int) -> str | None:
    """ "px4" / "ardupilot" from a heartbeat's ``autopilot`` field; None for anything else (a
    ground station, a companion computer)."""
    m = mavlink()
    if heartbeat_autopilot == m.MAV_AUTOPILOT_PX4:
        return "px4"
    if heartbeat_autopilot == m.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return "ardupilot"
    return None


def under_external_control(autopilot: str, custom_mode: int) -> bool:
    """Whether a heartbeat's mode is offboard (PX4) / guided (ArduPilot): the vehicle flies
    the set-points of its companion computer."""
    if autopilot == "px4":
        return (custom_mode >> 16) & 0xFF == PX4_MAIN_OFFBOARD
    return custom_mode == APM_GUIDED


# --- states ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class StateReport:
    """A position report in the world frame: from system ``source`` (an ``ADSB_VEHICLE``:
    ``icao`` set, the aircraft it describes), ``position`` and ``velocity`` ENU (m, m/s),
    ``kind`` the message name."""

    source: int
    kind: str
    position: np.ndarray
    velocity: np.ndarray
    icao: int | None = None


class Rejected(ValueError):
    """A message whose state is not finite or impossible; ``reason`` is the count's key."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


def _finite(values: Any, what: str) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(a)):
        raise Rejected("non_finite", f"{what} {a.tolist()}")
    return a


def _geodetic(lat_e7: int, lon_e7: int, what: str) -> tuple[float, float]:
    lat, lon = lat_e7 * DEG_E7, lon_e7 * DEG_E7
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise Rejected("impossible", f"{what} at latitude {lat}, longitude {lon}")
    return lat, lon


def read_state(msg: Any, frame: GeodeticFrame | None, local_origin: np.ndarray) -> StateReport:
    """The :class:`StateReport` of a ``LOCAL_POSITION_NED`` (placed at ``local_origin``, the
    world position of the autopilot's local origin), ``GLOBAL_POSITION_INT`` or
    ``ADSB_VEHICLE`` (both need the geodetic ``frame``); raises :class:`Rejected`."""
    kind, src = msg.get_type(), msg.get_srcSystem()
    if kind == "LOCAL_POSITION_NED":
        p = _finite((msg.x, msg.y, msg.z), "position")
        v = _finite((msg.vx, msg.vy, msg.vz), "velocity")
        return StateReport(src, kind, local_origin + ned_to_enu(p), ned_to_enu(v))
    if frame is None:
        raise Rejected("no_origin", f"{kind} needs --origin")
    if kind == "GLOBAL_POSITION_INT":
        lat, lon = _geodetic(msg.lat, msg.lon, kind)
        p = frame.to_world(lat, lon, msg.alt * MM)
        v = ned_to_enu((msg.vx * CM, msg.vy * CM, msg.vz * CM))
        return StateReport(src, kind, _finite(p, "position"), v)
    if kind == "ADSB_VEHICLE":
        return _adsb(msg, frame)
    raise Rejected("not_a_state", kind)


def _adsb(msg: Any, frame: GeodeticFrame) -> StateReport:
    m = mavlink()
    need = m.ADSB_FLAGS_VALID_COORDS | m.ADSB_FLAGS_VALID_ALTITUDE
    if msg.flags & need != need:
        raise Rejected("impossible", "ADSB_VEHICLE without valid coordinates and altitude")
    lat, lon = _geodetic(msg.lat, msg.lon, "ADSB_VEHICLE")
    p = _finite(frame.to_world(lat, lon, msg.altitude * MM), "position")
    v = np.zeros(3)
    horizontal = m.ADSB_FLAGS_VALID_HEADING | m.ADSB_FLAGS_VALID_VELOCITY
    if msg.flags & horizontal == horizontal:
        heading = np.deg2rad(msg.heading * CM)  # clockwise from north
        v[:2] = msg.hor_velocity * CM * np.array([np.sin(heading), np.cos(heading)])
    if msg.flags & m.ADSB_FLAGS_VERTICAL_VELOCITY_VALID:
        v[2] = msg.ver_velocity * CM
    return StateReport(msg.get_srcSystem(), "ADSB_VEHICLE", p, v, icao=int(msg.ICAO_address))


# --- encoders of the simulated vehicle ---------------------------------------------------------


def global_position(mav: Any, frame: GeodeticFrame, p: Any, v: Any, time_boot_ms: int) -> Any:
    """``GLOBAL_POSITION_INT`` of a world position and velocity (altitude also relative to the
    world's ground, ``relative_alt``)."""
    lat, lon, alt = frame.to_geodetic(p)
    vn, ve, vd = enu_to_ned(v)
    return mav.global_position_int_encode(
        int(time_boot_ms) & 0xFFFFFFFF,
        int(round(lat / DEG_E7)),
        int(round(lon / DEG_E7)),
        int(round(alt / MM)),
        int(round(float(p[2]) / MM)),
        _int16(vn / CM),
        _int16(ve / CM),
        _int16(vd / CM),
        65535,  # heading unknown
    )


def local_position(mav: Any, p: Any, v: Any, time_boot_ms: int) -> Any:
    """``LOCAL_POSITION_NED`` of a world position and velocity (local origin = world origin)."""
    n, e, d = enu_to_ned(p)
    vn, ve, vd = enu_to_ned(v)
    return mav.local_position_ned_encode(int(time_boot_ms) & 0xFFFFFFFF, n, e, d, vn, ve, vd)


def adsb_vehicle(mav: Any, frame: GeodeticFrame, p: Any, v: Any, icao: int) -> Any:
    """``ADSB_VEHICLE`` of a world position and velocity (geometric altitude)."""
    m = mavlink()
    lat, lon, alt = frame.to_geodetic(p)
    ground = float(np.hypot(v[0], v[1]))
    heading = float(np.rad2deg(np.arctan2(v[0], v[1]))) % 360.0
    flags = (
        m.ADSB_FLAGS_VALID_COORDS
        | m.ADSB_FLAGS_VALID_ALTITUDE
        | m.ADSB_FLAGS_VALID_HEADING
        | m.ADSB_FLAGS_VALID_VELOCITY
        | m.ADSB_FLAGS_VERTICAL_VELOCITY_VALID
        | m.ADSB_FLAGS_SIMULATED
    )
    return mav.adsb_vehicle_encode(
        icao,
        int(round(lat / DEG_E7)),
        int(round(lon / DEG_E7)),
        m.ADSB_ALTITUDE_TYPE_GEOMETRIC,
        int(round(alt / MM)),
        int(round(heading / CM)) % 36000,
        min(int(round(ground / CM)), 65535),
        _int16(float(v[2]) / CM),
        f"VO{icao % 10000:04d}".encode(),
        m.ADSB_EMITTER_TYPE_UAV,
        1,
        flags,
        0,
    )


def _int16(x: float) -> int:
    return int(np.clip(round(float(x)), -32768, 32767))


# --- signing -----------------------------------------------------------------------------------


def load_signing_key(path: str | Path) -> bytes:
    """The 32-byte MAVLink 2 signing key in ``path``: 32 raw bytes, or 64 hexadecimal digits
    (whitespace around them allowed). ``ValueError`` naming the file otherwise."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if len(data) == 32:
        return data
    text = data.strip()
    try:
        key = bytes.fromhex(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != 32:
        raise ValueError(f"{path}: a signing key is 32 bytes or 64 hexadecimal digits")
    return key
