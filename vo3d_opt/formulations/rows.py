"""The linearised VO rows of plane_qp, one per VO, plane and round (formulations/plane_qp.md).

On every avoidance plane P_phi the velocity is w = (x, y), v = x e1 + y e2(phi). Each section
of a VO becomes one half-plane G·w <= h on that plane:

- a conic section (circle, ellipse, parabola, hyperbola): the cone's tangent plane along the
  generator through a boundary point of the section (the curve points of eq. (12) and the
  chord points of eq. (17)), restricted to the plane. Round "near" takes the boundary point
  nearest the preferred velocity, "left" / "right" the nearest in the upper / lower half of
  the section. A tangent plane supports the (convex) cone, so no point of the half-plane is in
  the VO, and it is pushed out by ``margin`` (m/s) so that answers are strictly outside;
- a triangle (the apex on the plane, section 3.1.3, and every pyramid section, eq. 19): one of
  its two sides through the apex;
- A inside the zone: the escape half-plane (not closing in), every round; under a prism's top
  the QPs' climb row comes with the limits' (``Encounter.qp_bounds``).

Blank, point and line sections constrain nothing. The rows are compiled
(``vo3d_opt/algorithm/sections.hpp``: ``plane_rows``); the exact solver and every other backend
use these same rows (``kernel.PlaneQPs``).
"""

from __future__ import annotations

import numpy as np

import vo3d_opt._core as _core

#: Linearisation rounds: nearest boundary point, then every section passed on its left, right.
ROUNDS = ("near", "left", "right")


def py_pick(curve: np.ndarray, chord: np.ndarray, w0: np.ndarray) -> tuple[int, int, int]:
    """The boundary candidate each round linearises at (compiled: ``pick``), among the curve
    points ``curve`` (2, K) of eq. (12) and the chord points ``chord`` (2, 2) (rows: points) of
    eq. (17), NaN x where there is none: "near" the nearest to ``w0``, "left" / "right" the
    nearest in the upper / lower half of the section (by in-plane y about the candidates'
    mean), or the nearest when that half is empty."""
    return _core.pick(curve, chord, w0)
