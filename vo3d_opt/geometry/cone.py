"""VO cones of moving vehicles with spherical protected zones: eqs (1)–(6) and the virtual
sphere of section 3.1.6, vectorised over n neighbours."""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cached_property

import numpy as np

from .._jit import jit

#: The paper's smallest virtual-sphere factor (section 3.1.6: tau >= 1.5).
TAU_MIN = 1.5


@dataclass(frozen=True)
class VOCones:
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
    inside: np.ndarray  # (n,) bool: A is already inside B's protected zone (d_oi <= r_pz)

    def __len__(self) -> int:
        return len(self.d_oi)

    @property
    def axis(self) -> np.ndarray:
        """Unit symmetry-line direction (n, 3): from A towards B."""
        return self.R[:, :, 0]

    @cached_property
    def sin_alpha(self) -> np.ndarray:
        """Sine of the half-angle alpha of the cone: r_pz / d_oi."""
        return np.clip(self.r_pz / np.maximum(self.d_oi, 1e-12), 0.0, 1.0)

    @cached_property
    def cos_alpha(self) -> np.ndarray:
        return np.sqrt(1.0 - self.sin_alpha**2)

    @property
    def center(self) -> np.ndarray:
        """C_vo of eq. (5), (n, 3)."""
        return self.apex + self.d_vo[:, None] * self.axis

    def min_speed(self) -> np.ndarray:
        """(n,) the smallest |v| inside each VO: the distance from the velocity origin to the
        (infinite) cone; 0 when A is inside the zone or the origin is in the cone."""
        return _min_speed_kernel(self.apex, self.R, self.r_pz, self.d_oi, self.inside)

    def subset(self, keep: np.ndarray) -> "VOCones":
        """The cones selected by the boolean or index array ``keep``."""
        return VOCones(**{f.name: getattr(self, f.name)[keep] for f in fields(self)})

    def base_points(self, t: np.ndarray) -> np.ndarray:
        """B_vo(t) of eq. (4) for angles t (K,), shape (n, K, 3)."""
        body = np.stack(
            [
                np.broadcast_to(self.d_vo[:, None], (len(self), len(t))),
                self.r_vo[:, None] * np.cos(t),
                self.r_vo[:, None] * np.sin(t),
            ],
            axis=-1,
        )
        return body @ self.R.transpose(0, 2, 1) + self.apex[:, None, :]

    def outward_normals(self, t: np.ndarray) -> np.ndarray:
        """Unit outward normal of the cone surface along the generator through B_vo(t).

        ``t`` has shape (n, ...); the result (n, ..., 3). The plane through the apex with this
        normal is tangent to the cone along the whole generator: a supporting plane."""
        t = np.asarray(t, dtype=float)
        flat = np.ascontiguousarray(t.reshape(len(self), -1))
        out = np.empty(flat.shape + (3,))
        for i in range(len(self)):
            for k in range(flat.shape[1]):
                out[i, k] = outward_normal(self.R[i], float(self.sin_alpha[i]), float(flat[i, k]))
        return out.reshape(t.shape + (3,))


def vo_cones(
    p_A: np.ndarray,
    p_B: np.ndarray,
    V_B: np.ndarray,
    r_pz: np.ndarray,
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
    paper's rule applies: tau = tau_min when A is within 2 r_pz of B.
    """
    p_B = np.ascontiguousarray(p_B, dtype=float).reshape(-1, 3)
    r_pz = np.broadcast_to(np.asarray(r_pz, dtype=float), (len(p_B),)).copy()
    a = np.ascontiguousarray(V_B if apex is None else apex, dtype=float).reshape(-1, 3)
    mode = -1.0 if not virtual_sphere else (np.nan if reach is None else float(reach))
    rel, d_oi, theta_el, psi_az, R, d_vo, r_vo, tau = _cone_kernel(
        np.asarray(p_A, dtype=float), p_B, a, r_pz, mode, float(tau_min))
    return VOCones(rel=rel, apex=a, r_pz=r_pz, d_oi=d_oi, theta_el=theta_el, psi_az=psi_az, R=R,
                   d_vo=d_vo, r_vo=r_vo, tau=tau, inside=d_oi <= r_pz)


@jit
def outward_normal(R: np.ndarray, sin_alpha: float, t: float) -> tuple[float, float, float]:
    """The cone's unit outward normal along the generator through B_vo(t): R_{theta_el|psi_az}
    (eq. 6) applied to (-sin alpha, cos alpha cos t, cos alpha sin t) in the cone's own frame."""
    ca = np.sqrt(1.0 - sin_alpha * sin_alpha)
    b0, b1, b2 = -sin_alpha, ca * np.cos(t), ca * np.sin(t)
    return (R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2, R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2,
            R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2)


@jit
def _cone_kernel(p_A, p_B, apex, r_pz, reach, tau_min):
    """Eqs (1), (2), (6) and the virtual-sphere factor for every neighbour. ``reach``: NaN for
    the paper's rule, negative for no virtual sphere."""
    n = p_B.shape[0]
    rel, R = np.empty((n, 3)), np.empty((n, 3, 3))
    d_oi, theta_el, psi_az = np.empty(n), np.empty(n), np.empty(n)
    d_vo, r_vo, tau = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        for k in range(3):
            rel[i, k] = p_B[i, k] - p_A[k]
        d = np.sqrt(rel[i, 0] ** 2 + rel[i, 1] ** 2 + rel[i, 2] ** 2)  # eq. (1)
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
    return rel, d_oi, theta_el, psi_az, R, d_vo, r_vo, tau


@jit
def _min_speed_kernel(apex, R, r_pz, d_oi, inside):
    n = apex.shape[0]
    out = np.zeros(n)
    for i in range(n):
        if inside[i]:
            continue
        L = np.sqrt(apex[i, 0] ** 2 + apex[i, 1] ** 2 + apex[i, 2] ** 2)
        cos_b = -(apex[i, 0] * R[i, 0, 0] + apex[i, 1] * R[i, 1, 0] + apex[i, 2] * R[i, 2, 0]) / max(L, 1e-12)
        beta = np.arccos(min(max(cos_b, -1.0), 1.0))
        alpha = np.arcsin(min(max(r_pz[i] / max(d_oi[i], 1e-12), 0.0), 1.0))
        if beta <= alpha:  # the origin is in the cone
            out[i] = 0.0
        elif beta >= alpha + np.pi / 2:  # the apex is the nearest point
            out[i] = L
        else:
            out[i] = L * np.sin(beta - alpha)
    return out
