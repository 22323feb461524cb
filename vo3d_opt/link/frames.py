"""MAVLink's frames and the project's world frame.

The world frame of a scenario is ENU: x east, y north, z up (altitude above the scenario's
ground). MAVLink's local frame (``MAV_FRAME_LOCAL_NED``: ``LOCAL_POSITION_NED``,
``SET_POSITION_TARGET_LOCAL_NED``) is NED: x north, y east, z down. Geodetic messages
(``GLOBAL_POSITION_INT``, ``ADSB_VEHICLE``) give latitude, longitude and altitude; they are
placed in the world frame by :class:`GeodeticFrame`, the local tangent plane at the scenario's
origin (its ``lat, lon, alt`` given with ``vo3d link --origin``), computed by PROJ through
pyproj (``+proj=topocentric`` on WGS 84): no hand-written ellipsoid formulas.

Velocities in the geodetic messages are north/east/down components in the vehicle's own
tangent plane; they are used as world components as they are (the tangent planes at the
origin and at a vehicle 300 m off differ by 300 / 6.4e6 = 47 micro-radians: 0.2 mm/s at 4 m/s).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from vo3d_opt.extras import needs

#: NED <-> ENU is its own inverse: swap the two horizontal axes, flip the vertical one.
_SWAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def ned_to_enu(v: Any) -> np.ndarray:
    """(north, east, down) -> (east, north, up), for one vector (3,) or many (N, 3)."""
    return np.asarray(v, dtype=float) @ _SWAP.T


def enu_to_ned(v: Any) -> np.ndarray:
    """(east, north, up) -> (north, east, down), for one vector (3,) or many (N, 3)."""
    return np.asarray(v, dtype=float) @ _SWAP.T


def parse_origin(text: str) -> tuple[float, float, float]:
    """``"LAT,LON,ALT"`` (degrees, degrees, metres) -> a checked triple; ``ValueError`` naming
    what is wrong."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3:
        raise ValueError(f"{text!r}: expected LAT,LON,ALT (degrees, degrees, metres)")
    try:
        lat, lon, alt = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{text!r}: LAT, LON and ALT must be numbers") from None
    if not all(np.isfinite((lat, lon, alt))):
        raise ValueError(f"{text!r}: LAT, LON and ALT must be finite")
    if not -90.0 <= lat <= 90.0:
        raise ValueError(f"{text!r}: latitude {lat} is outside [-90, 90]")
    if not -180.0 <= lon <= 180.0:
        raise ValueError(f"{text!r}: longitude {lon} is outside [-180, 180]")
    return lat, lon, alt


class GeodeticFrame:
    """The world frame anchored at a geodetic origin: ``lat``, ``lon`` (degrees, WGS 84) and
    ``alt`` (metres) of the world's (0, 0, 0). ``alt`` must be in the same altitude system as
    the messages' altitudes (MAVLink's ``GLOBAL_POSITION_INT.alt`` is above mean sea level on
    PX4 and ArduPilot): the conversion treats both as heights over the ellipsoid, and the
    difference between the two systems (the geoid's height) is the same for the origin and
    for points a few kilometres around it, so it cancels."""

    def __init__(self, lat: float, lon: float, alt: float) -> None:
        with needs("link", "geodesy"):
            from pyproj import Transformer

        self.origin = (float(lat), float(lon), float(alt))
        pipeline = (
            "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
            "+step +proj=cart +ellps=WGS84 "
            f"+step +proj=topocentric +ellps=WGS84 +lat_0={lat!r} +lon_0={lon!r} +h_0={alt!r}"
        )
        self._t = Transformer.from_pipeline(pipeline)

    def to_world(self, lat: Any, lon: Any, alt: Any) -> np.ndarray:
        """Geodetic -> world ENU (m): (3,) for scalars, (N, 3) for arrays."""
        e, n, u = self._t.transform(lon, lat, alt)
        return np.stack(np.broadcast_arrays(e, n, u), axis=-1).astype(float)

    def to_geodetic(self, xyz: Any) -> np.ndarray:
        """World ENU (3,) or (N, 3) -> (lat, lon, alt) (3,) or (N, 3)."""
        p = np.asarray(xyz, dtype=float)
        lon, lat, alt = self._t.transform(p[..., 0], p[..., 1], p[..., 2], direction="INVERSE")
        return np.stack(np.broadcast_arrays(lat, lon, alt), axis=-1).astype(float)
