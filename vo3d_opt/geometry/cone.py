"""VO cones of moving vehicles with spherical protected zones: eqs (1)–(6) and the virtual
sphere of section 3.1.6, for n neighbours at once.

``VOCones`` is a NamedTuple of arrays; the compiled core (``vo3d_opt._core``, whose algorithm
reads in ``vo3d_opt/algorithm/vo.hpp``) builds its fields and ``vo_cones`` is the Python front end.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import vo3d_opt._core as _core

#: The paper's smallest virtual-sphere factor (section 3.1.6: tau >= 1.5).
TAU_MIN = 1.5
#: ``reach`` values of build_cones that are not speeds: the paper's rule, or no virtual sphere.
PAPER_RULE, NO_VIRTUAL_SPHERE = np.nan, -1.0


class VOCones(NamedTuple):
    """n VO cones seen from the avoiding vehicle A. Velocities are in m/s, the cone's length
    d_vo in the same units (the paper draws the collision cone to scale in velocity space)."""

    rel: np.ndarray  # (n, 3) p_B - p_A
    apex: np.ndarray  # (n, 3) A_vo = V_B (eq. 3), or (V_A + V_B)/2 when reciprocal
    r_pz: np.ndarray  # (n,)
    d_oi: np.ndarray  # (n,) eq. (1)
    theta_el: np.ndarray  # (n,) eq. (1)
    psi_az: np.ndarray  # (n,) eq. (1)
    R: np.ndarray  # (n, 3, 3) eq. (6); column 0 is the cone axis
    d_vo: np.ndarray  # (n,) eq. (2), times tau
    r_vo: np.ndarray  # (n,) eq. (2), times tau
    tau: np.ndarray  # (n,) virtual-sphere factor (section 3.1.6); 1 when not expanded
    sin_alpha: np.ndarray  # (n,) sine of the half-angle alpha: r_pz / d_oi (1 inside the zone)
    inside: np.ndarray  # (n,) bool: A is already inside B's protected zone (d_oi <= r_pz)

    @classmethod
    def empty(cls) -> VOCones:
        """No cones: membership and clearance of obstacles alone."""
        return cls(
            rel=np.zeros((0, 3)),
            apex=np.zeros((0, 3)),
            r_pz=np.zeros(0),
            d_oi=np.zeros(0),
            theta_el=np.zeros(0),
            psi_az=np.zeros(0),
            R=np.zeros((0, 3, 3)),
            d_vo=np.zeros(0),
            r_vo=np.zeros(0),
            tau=np.zeros(0),
            sin_alpha=np.zeros(0),
            inside=np.zeros(0, dtype=bool),
        )

    @property
    def n(self) -> int:
        return int(self.d_oi.shape[0])

    @property
    def axis(self) -> np.ndarray:
        """Unit symmetry-line direction (n, 3): from A towards B."""
        return self.R[:, :, 0]

    @property
    def cos_alpha(self) -> np.ndarray:
        return np.sqrt(1.0 - self.sin_alpha**2)

    @property
    def center(self) -> np.ndarray:
        """C_vo of eq. (5), (n, 3)."""
        return self.apex + self.d_vo[:, None] * self.axis

    def subset(self, keep: np.ndarray) -> VOCones:
        """The cones selected by the boolean or index array ``keep``."""
        return VOCones(*(np.ascontiguousarray(field[keep]) for field in self))

    def base_points(self, t: np.ndarray) -> np.ndarray:
        """B_vo(t) of eq. (4) for angles t (K,), shape (n, K, 3)."""
        body = np.stack(
            [
                np.broadcast_to(self.d_vo[:, None], (self.n, len(t))),
                self.r_vo[:, None] * np.cos(t),
                self.r_vo[:, None] * np.sin(t),
            ],
            axis=-1,
        )
        return body @ self.R.transpose(0, 2, 1) + self.apex[:, None, :]


def vo_cones(
    p_A: np.ndarray,
    p_B: np.ndarray,
    V_B: np.ndarray,
    r_pz: np.ndarray | float,
    *,
    reach: float | None = None,
    virtual_sphere: bool = True,
    tau_min: float = TAU_MIN,
    apex: np.ndarray | None = None,
) -> VOCones:
    """Build the VO cones of eqs (1)–(6) for neighbours at ``p_B`` (n, 3) moving at ``V_B``.

    ``reach`` is the largest own speed of interest (m/s). With ``virtual_sphere`` (section
    3.1.6) a cone whose base lies inside that reach is lengthened by the factor
    tau = max(tau_min, needed) (the virtual sphere tau·r_pz at tau·|p_B - p_A|, eq. 18), so that
    its finite conic sections are exact for every speed up to ``reach``. Without ``reach`` the
    paper's rule applies: tau = tau_min when A is within 2 r_pz of B. ``apex`` replaces V_B as
    the apex (the reciprocal apex (V_A + V_B)/2).
    """
    p_B = np.ascontiguousarray(p_B, dtype=float).reshape(-1, 3)
    r_pz = np.broadcast_to(np.asarray(r_pz, dtype=float), (len(p_B),)).copy()
    a = np.ascontiguousarray(V_B if apex is None else apex, dtype=float).reshape(-1, 3)
    mode = (
        NO_VIRTUAL_SPHERE if not virtual_sphere else (PAPER_RULE if reach is None else float(reach))
    )
    return py_build_cones(np.asarray(p_A, dtype=float), p_B, a, r_pz, mode, float(tau_min))


def py_build_cones(
    p_A: np.ndarray,
    p_B: np.ndarray,
    apex: np.ndarray,
    r_pz: np.ndarray,
    reach: float,
    tau_min: float,
) -> VOCones:
    """Eqs (1), (2), (6) and the virtual-sphere factor for every neighbour (compiled:
    ``build_cone``). ``reach``: the largest own speed, PAPER_RULE (NaN) for the paper's rule,
    NO_VIRTUAL_SPHERE (< 0) for none."""
    return VOCones(*_core.build_cones(p_A, p_B, apex, r_pz, float(reach), float(tau_min)))


def outward_normals(cones: VOCones, t: np.ndarray) -> np.ndarray:
    """(n, K, 3) each cone's unit outward normal along the generators through B_vo(t) (eq. 6
    applied to (-sin alpha, cos alpha cos t, cos alpha sin t)): the normal of a supporting plane
    of the (convex) VO, touching it along the whole generator."""
    return _core.outward_normals(
        cones.R, cones.sin_alpha, np.ascontiguousarray(np.atleast_1d(np.asarray(t, dtype=float)))
    )


def min_speeds(cones: VOCones) -> np.ndarray:
    """(n,) the smallest |v| inside each VO cone: the distance from the velocity origin to the
    (infinite) cone; 0 when A is inside the zone or the origin is in the cone."""
    return _core.min_speeds(cones)


#: The constructor by the name the package exports (``vo3d_opt.geometry.build_cones``).
build_cones = py_build_cones
