"""Rotations of the paper (eqs 6 and 8) and the avoidance planes P_phi (section 2.1.1).

Frame choice (documented in formulations/geometry.md): every avoidance plane passes through the
origin of velocity space and contains one common axis e_x, the preferred-velocity direction, so
the preferred velocity lies in every plane. e_y0 is horizontal (left of e_x) and e_z0 = e_x × e_y0
points up; P_phi is spanned by e_x and e2(phi) = cos(phi) e_y0 + sin(phi) e_z0, so P_0 is the most
horizontal plane and phi runs from -90° to 90°. Eq. (8) is the rotation that takes a vector's
(e_x, e_y0, e_z0) coordinates to (x^phi, y^phi, z^phi), z^phi = 0 being the plane itself.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

import vo3d_opt._core as _core


class AvoidancePlanes(NamedTuple):
    """P avoidance planes through the velocity-space origin sharing the axis e1.

    ``to_plane`` (P, 3, 3) maps world vectors to plane coordinates (x^phi, y^phi, z^phi);
    its rows are e1, e2(phi) and the plane normal n(phi)."""

    phi: np.ndarray  # (P,) rad
    frame: np.ndarray  # (3, 3) rows e_x, e_y0, e_z0
    to_plane: np.ndarray  # (P, 3, 3) = R_{P_phi} @ frame

    @property
    def e1(self) -> np.ndarray:
        return self.frame[0]

    @property
    def e2(self) -> np.ndarray:
        """(P, 3) the in-plane direction e2(phi) of every plane."""
        return self.to_plane[:, 1, :]

    @property
    def normal(self) -> np.ndarray:
        return self.to_plane[:, 2, :]

    def lift(self, xy: np.ndarray) -> np.ndarray:
        """Plane coordinates (P, ..., 2) to world velocities (P, ..., 3)."""
        e1, e2 = self.e1, self.e2
        shape = (len(self.phi),) + (1,) * (xy.ndim - 2) + (3,)
        return xy[..., :1] * e1 + xy[..., 1:2] * e2.reshape(shape)

    def coords(self, v: np.ndarray) -> np.ndarray:
        """Plane coordinates of per-shape vectors: v (n, ..., 3) -> (n, P, ..., 3).

        Eq. (8) as a rotation about the common axis: x is the same on every plane, so only the
        (e_y0, e_z0) components are rotated, which is much cheaper than P full products."""
        f = v @ self.frame.T  # (n, ..., 3) in (e_x, e_y0, e_z0)
        shape = (1, len(self.phi)) + (1,) * (f.ndim - 2)
        c, s = np.cos(self.phi).reshape(shape), np.sin(self.phi).reshape(shape)
        f1, f2 = f[:, None, ..., 1], f[:, None, ..., 2]
        x = np.broadcast_to(f[:, None, ..., 0], np.broadcast_shapes(f1.shape, c.shape))
        return np.stack([x, c * f1 + s * f2, c * f2 - s * f1], axis=-1)

    def project(self, v: np.ndarray) -> np.ndarray:
        """World vectors (..., 3) to coordinates on every plane (P, ..., 3)."""
        return np.einsum("pij,...j->p...i", self.to_plane, v)


def avoidance_frame(direction: np.ndarray) -> np.ndarray:
    """Rows e_x (unit ``direction``), e_y0 (horizontal, left of e_x), e_z0 = e_x × e_y0 (up)."""
    return _core.avoidance_frame(direction)


def py_build_planes(direction: np.ndarray, phi: np.ndarray) -> AvoidancePlanes:
    """The planes P_phi for angles ``phi`` (rad) about the axis ``direction``: eq. (8),
    R_{P_phi} @ frame for every phi (compiled: ``build_planes``; the rotation only mixes e_y0
    and e_z0)."""
    return AvoidancePlanes(*_core.build_planes(direction, phi))


#: The constructor by the name the package exports (``vo3d_opt.geometry.build_planes``).
build_planes = py_build_planes


def avoidance_planes(direction: np.ndarray, phi: np.ndarray) -> AvoidancePlanes:
    """The planes P_phi for angles ``phi`` (rad) about the axis ``direction``."""
    return py_build_planes(
        np.asarray(direction, dtype=float).reshape(3),
        np.ascontiguousarray(np.atleast_1d(np.asarray(phi, dtype=float))),
    )


@functools.lru_cache(maxsize=16)
def _phis(step_deg: float) -> np.ndarray:
    phi = np.deg2rad(np.arange(-90.0, 90.0 + 1e-9, step_deg))
    phi.setflags(write=False)
    return phi


def default_phis(step_deg: float = 10.0) -> np.ndarray:
    """Plane angles from -90° to 90° every ``step_deg`` (the paper's P_-90 … P_90)."""
    if not (0 < step_deg <= 180):
        raise ValueError("plane_step_deg must be in (0, 180]")
    return _phis(float(step_deg))
