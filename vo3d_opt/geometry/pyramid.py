"""VO pyramids of static obstacles (section 4), vectorised over m obstacles.

Each cylinder or box gets a tall square protected prism C_pz of side L_pz and height h_pz standing
on the ground, centred on the obstacle and turned so that one face is square to the horizontal
line of sight from A (section 4.1). With V_B = 0 the VO pyramid equals the collision pyramid: the
set of velocities whose ray from p_A enters C_pz. Its apex is the velocity origin (eq. 19); the
paper's base B_vo is the near face (eqs 20–22, lines L1–L4). We span the pyramid by all eight
corners of C_pz: for a vehicle below h_pz this is exactly the near-face pyramid; above h_pz the top
face is seen too and belongs to the obstacle's shadow (see formulations/geometry.md).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from ..types import Box, Cylinder

# Corner k of the prism in its frame: bits (far, left, top) of k.
_CORNER_BITS = np.array([[(k >> 0) & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], dtype=float)
#: The 12 edges of a box as pairs of corner indices (corners differing in one bit).
BOX_EDGES = np.array([(a, a | (1 << b)) for a in range(8) for b in range(3) if not a & (1 << b)])


@dataclass(frozen=True)
class VOPyramids:
    """m VO pyramids seen from A. ``frame`` rows: h (horizontal, towards the obstacle), s
    (horizontal, left), z (up). The prism is [lo, hi] in frame coordinates relative to p_A."""

    frame: np.ndarray  # (m, 3, 3)
    lo: np.ndarray  # (m, 3)
    hi: np.ndarray  # (m, 3)
    L_pz: np.ndarray  # (m,)
    h_pz: np.ndarray  # (m,)
    inside: np.ndarray  # (m,) bool: A already inside C_pz

    def __len__(self) -> int:
        return len(self.L_pz)

    def subset(self, keep: np.ndarray) -> "VOPyramids":
        """The pyramids selected by the boolean or index array ``keep``."""
        return VOPyramids(**{f.name: getattr(self, f.name)[keep] for f in fields(self)})

    @property
    def corners(self) -> np.ndarray:
        """The eight corners of C_pz relative to p_A, world frame, (m, 8, 3)."""
        local = self.lo[:, None, :] + _CORNER_BITS[None] * (self.hi - self.lo)[:, None, :]
        return np.einsum("mki,mij->mkj", local, self.frame)

    @property
    def near_face(self) -> np.ndarray:
        """The paper's base rectangle B_vo (near face, corners in order), (m, 4, 3)."""
        return self.corners[:, [0, 2, 6, 4], :]


def _footprint_centers(obstacles: Sequence[Cylinder | Box]) -> np.ndarray:
    return np.array([o.center for o in obstacles], dtype=float).reshape(-1, 2)


def vo_pyramids(p_A: np.ndarray, obstacles: Sequence[Cylinder | Box]) -> VOPyramids:
    """Build the VO pyramids of static cylinders and boxes seen from ``p_A``."""
    p_A = np.asarray(p_A, dtype=float)
    m = len(obstacles)
    centers = _footprint_centers(obstacles)
    L = np.array([o.side for o in obstacles], dtype=float)
    H = np.array([o.prism_height for o in obstacles], dtype=float)
    d_xy = centers - p_A[:2]
    dist = np.linalg.norm(d_xy, axis=1)
    h = np.where(dist[:, None] > 1e-9, d_xy / np.maximum(dist, 1e-12)[:, None], [1.0, 0.0])
    frame = np.zeros((m, 3, 3))
    frame[:, 0, :2] = h
    frame[:, 1, 0], frame[:, 1, 1] = -h[:, 1], h[:, 0]
    frame[:, 2, 2] = 1.0
    lo = np.stack([dist - L / 2, -L / 2, -np.full(m, p_A[2])], axis=1)
    hi = np.stack([dist + L / 2, L / 2, H - p_A[2]], axis=1)
    # Turned to face A, the square contains A exactly when A is within its apothem L/2.
    inside = (dist < L / 2) & (p_A[2] < H)
    return VOPyramids(frame=frame, lo=lo, hi=hi, L_pz=L, h_pz=H, inside=inside)
