"""VO pyramids of static obstacles (section 4), vectorised over m obstacles.

Each cylinder or box gets a tall square protected prism C_pz of side L_pz and height h_pz standing
on the ground, centred on the obstacle and turned so that one face is square to the horizontal
line of sight from A (section 4.1); its bottom lies 10 km below the ground (``UNDERGROUND`` in
algorithm/vo.hpp), so that a ray under the floor is no way past the obstacle. With V_B = 0 the VO
pyramid equals the collision pyramid: the set of velocities whose ray from p_A enters C_pz. Its
apex is the velocity origin (eq. 19); the paper's base B_vo is the near face (eqs 20–22, lines
L1–L4). We span the pyramid by all eight
corners of C_pz: for a vehicle below h_pz this is exactly the near-face pyramid; above h_pz the top
face is seen too and belongs to the obstacle's shadow (see formulations/geometry.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

import vo3d_opt._core as _core

from ..types import Box, Cylinder

#: The 12 edges of a box as pairs of corner indices (corners differing in one bit).
BOX_EDGES = np.array([(a, a | (1 << b)) for a in range(8) for b in range(3) if not a & (1 << b)])


class VOPyramids(NamedTuple):
    """m VO pyramids seen from A. ``frame`` rows: h (horizontal, towards the obstacle), s
    (horizontal, left), z (up). The prism is [lo, hi] in frame coordinates relative to p_A."""

    frame: np.ndarray  # (m, 3, 3)
    lo: np.ndarray  # (m, 3)
    hi: np.ndarray  # (m, 3)
    L_pz: np.ndarray  # (m,)
    h_pz: np.ndarray  # (m,)
    inside: np.ndarray  # (m,) bool: A already inside C_pz
    over_roof: np.ndarray  # (m,) bool: ... and over the obstacle's roof (within its rim, above it)

    @classmethod
    def empty(cls) -> VOPyramids:
        """No pyramids: membership and clearance of neighbours alone."""
        return cls(
            frame=np.zeros((0, 3, 3)),
            lo=np.zeros((0, 3)),
            hi=np.zeros((0, 3)),
            L_pz=np.zeros(0),
            h_pz=np.zeros(0),
            inside=np.zeros(0, dtype=bool),
            over_roof=np.zeros(0, dtype=bool),
        )

    @property
    def n(self) -> int:
        return int(self.L_pz.shape[0])

    def subset(self, keep: np.ndarray) -> VOPyramids:
        """The pyramids selected by the boolean or index array ``keep``."""
        return VOPyramids(*(np.ascontiguousarray(field[keep]) for field in self))

    @property
    def corners(self) -> np.ndarray:
        """The eight corners of C_pz relative to p_A, world frame, (m, 8, 3)."""
        return prism_corners(self.frame, self.lo, self.hi)

    @property
    def near_face(self) -> np.ndarray:
        """The paper's base rectangle B_vo (near face, corners in order), (m, 4, 3)."""
        return self.corners[:, [0, 2, 6, 4], :]


def prism_corners(frame: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Corner k of each prism (bits far, left, top of k pick hi over lo), world frame (m, 8, 3)."""
    return _core.prism_corners(frame, lo, hi)


#: The width of an obstacle's prism row: x, y, L_pz, h_pz, the obstacle's height and its rim
#: (``Cylinder.prism``); rows of the first four alone are read as having no roof.
PRISM_WIDTH = 6


def prism_rows(obstacles: Sequence[Cylinder | Box]) -> np.ndarray:
    """(m, 6) the prism rows (``PRISM_WIDTH``) of static cylinders and boxes."""
    return np.array([o.prism for o in obstacles], dtype=float).reshape(-1, PRISM_WIDTH)


def vo_pyramids(p_A: np.ndarray, obstacles: Sequence[Cylinder | Box]) -> VOPyramids:
    """Build the VO pyramids of static cylinders and boxes seen from ``p_A``."""
    return py_build_pyramids(np.asarray(p_A, dtype=float), prism_rows(obstacles))


def py_build_pyramids(p_A: np.ndarray, prisms: np.ndarray) -> VOPyramids:
    """Section 4.1 for prisms (m, 4) x, y, L_pz, h_pz, or (m, 6) with the obstacles' height
    and rim (``prism_rows``): C_pz turned square to the line of sight (compiled:
    ``build_pyramid``)."""
    return VOPyramids(*_core.build_pyramids(p_A, prisms))


#: The constructor by the name the package exports (``vo3d_opt.geometry.build_pyramids``).
build_pyramids = py_build_pyramids


def supporting_faces(pyr: VOPyramids, v0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each pyramid the supporting plane through the apex (origin) and two corners of C_pz
    that v0 is least inside of: N·v >= 0 keeps v out of the pyramid."""
    corners = pyr.corners  # (m, 8, 3)
    i, j = np.triu_indices(8, 1)
    N = np.cross(corners[:, i], corners[:, j])  # (m, 28, 3) candidate planes through the apex
    N /= np.maximum(np.linalg.norm(N, axis=-1, keepdims=True), 1e-12)
    side = np.einsum("mfi,mki->mfk", N, corners)
    # A supporting plane has every corner on one side; orient it so the corners are behind it.
    outward = np.all(side <= 1e-9, axis=-1)
    inward = np.all(side >= -1e-9, axis=-1)
    N = np.where(inward[..., None] & ~outward[..., None], -N, N)
    supporting = outward | inward
    score = np.where(supporting, N @ v0, -np.inf)
    best = np.argmax(score, axis=1)
    Nb = N[np.arange(pyr.n), best]
    # inside: the side's escape, horizontal and outwards (under the top, the QPs' climb row too)
    Nb = np.where(pyr.inside[:, None], -pyr.frame[:, 0, :], Nb)
    return Nb, np.zeros(pyr.n)
