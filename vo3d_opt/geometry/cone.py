"""VO cones of moving vehicles with spherical protected zones: eqs (1)–(6) and the virtual
sphere of section 3.1.6, for n neighbours at once.

``VOCones`` is a NamedTuple of arrays, so the same value flows through Python and compiled code
(numba reads its fields by name); ``build_cones`` is the compiled constructor and ``vo_cones``
its Python front end.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._jit import entry, inline, jit

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


@inline
def outward_normal(
    R: np.ndarray, sin_alpha: float, cos_t: float, sin_t: float
) -> tuple[float, float, float]:
    """The cone's unit outward normal along the generator through B_vo(t): R_{theta_el|psi_az}
    (eq. 6) applied to (-sin alpha, cos alpha cos t, cos alpha sin t) in the cone's own frame.
    The plane through the apex with this normal touches the cone along the whole generator: a
    supporting plane of the (convex) VO."""
    ca = np.sqrt(1.0 - sin_alpha * sin_alpha)
    b0, b1, b2 = -sin_alpha, ca * cos_t, ca * sin_t
    return (
        R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2,
        R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2,
        R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2,
    )


@inline
def offset(p_B: np.ndarray, p_A: np.ndarray, rel: np.ndarray) -> float:
    """p_B - p_A into rel (3,), and its length d_oi (eq. 1)."""
    for k in range(3):
        rel[k] = p_B[k] - p_A[k]
    return np.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2)


@jit
def build_cones(
    p_A: np.ndarray,
    p_B: np.ndarray,
    apex: np.ndarray,
    r_pz: np.ndarray,
    reach: float,
    tau_min: float,
) -> VOCones:
    """Eqs (1), (2), (6) and the virtual-sphere factor for every neighbour. ``reach``: the
    largest own speed, PAPER_RULE (NaN) for the paper's rule, NO_VIRTUAL_SPHERE (< 0) for none."""
    n = p_B.shape[0]
    rel, R = np.empty((n, 3)), np.empty((n, 3, 3))
    d_oi, theta_el, psi_az = np.empty(n), np.empty(n), np.empty(n)
    d_vo, r_vo, tau, sin_alpha = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        d = offset(p_B[i], p_A, rel[i])  # eq. (1)
        safe_d = max(d, 1e-12)
        th = np.arcsin(min(max(rel[i, 2] / safe_d, -1.0), 1.0))  # eq. (1), = atan(dz / dxy)
        ps = np.arctan2(rel[i, 1], rel[i, 0])  # eq. (1)
        ct, st, cp, sp = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
        # eq. (6): columns are the axis, the horizontal side and the 'up' side
        R[i, 0, 0], R[i, 0, 1], R[i, 0, 2] = cp * ct, -sp, -cp * st
        R[i, 1, 0], R[i, 1, 1], R[i, 1, 2] = sp * ct, cp, -sp * st
        R[i, 2, 0], R[i, 2, 1], R[i, 2, 2] = st, 0.0, ct
        # eq. (2): the tangent circle of the cone on the sphere, at distance d_vo along the axis
        dd = max(d * d - r_pz[i] ** 2, 0.0)
        dv, rv = dd / safe_d, r_pz[i] * np.sqrt(dd) / safe_d
        t = 1.0
        if d > r_pz[i]:  # never expanded when A is inside the zone
            if np.isnan(reach):
                t = tau_min if d < 2.0 * r_pz[i] else 1.0
            elif reach >= 0.0:
                # The base must lie beyond every |v| <= reach: axial(v - apex) <= reach + |apex|.
                a_len = np.sqrt(apex[i, 0] ** 2 + apex[i, 1] ** 2 + apex[i, 2] ** 2)
                needed = (reach + a_len) / max(dv, 1e-12)
                t = max(tau_min, needed * 1.01) if needed > 1.0 else 1.0
        d_oi[i], theta_el[i], psi_az[i] = d, th, ps
        d_vo[i], r_vo[i], tau[i] = dv * t, rv * t, t
        sin_alpha[i] = min(max(r_pz[i] / safe_d, 0.0), 1.0)
    return VOCones(
        rel,
        apex.copy(),
        r_pz.copy(),
        d_oi,
        theta_el,
        psi_az,
        R,
        d_vo,
        r_vo,
        tau,
        sin_alpha,
        d_oi <= r_pz,
    )


@entry
def py_build_cones(
    p_A: np.ndarray,
    p_B: np.ndarray,
    apex: np.ndarray,
    r_pz: np.ndarray,
    reach: float,
    tau_min: float,
) -> VOCones:
    """``build_cones`` for Python callers (compiled code calls ``build_cones``: no Python
    wrapper)."""
    return build_cones(p_A, p_B, apex, r_pz, reach, tau_min)


@inline
def min_speed(cones: VOCones, i: int) -> float:
    """The smallest |v| inside VO cone i: the distance from the velocity origin to the
    (infinite) cone; 0 when A is inside the zone or the origin is in the cone."""
    if cones.inside[i]:
        return 0.0
    a, R = cones.apex[i], cones.R[i]
    L = np.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2)
    cos_b = -(a[0] * R[0, 0] + a[1] * R[1, 0] + a[2] * R[2, 0]) / max(L, 1e-12)
    beta = np.arccos(min(max(cos_b, -1.0), 1.0))
    alpha = np.arcsin(cones.sin_alpha[i])
    if beta <= alpha:  # the origin is in the cone
        return 0.0
    if beta >= alpha + np.pi / 2:  # the apex is the nearest point
        return L
    return L * np.sin(beta - alpha)
