"""Conic sections of VO cones and VO pyramids on the avoidance planes (sections 3.1 and 4.2).

Every section is described the paper's way, in plane coordinates (x^phi, y^phi):
the curve of eq. (12) (generators of the cone meeting the plane), the two points of eq. (17)
where the base circle B_vo meets it (the "chord"), the projected apex A^phi, the symmetry-line
point H of eq. (13), and the VOlineL / VOlineR rays of section 3.1.5. ``Sections.contains`` says
whether in-plane velocities lie inside the section: inside the polygon through the curve and
chord points (or the triangle), or between the VO lines beyond the chord.

The six corrections of section 3.1 can be switched off one by one (``corrections``) to show what
the original formulas of Jenie et al. get wrong; the default applies all of them:

- ``tg_range``       3.1.1  keep curve points with 0 <= t_g <= 1 only (no spurious branch);
- ``symmetry_abs``   3.1.2  H uses |t_h| (no error side, any plane cutting the axis line);
- ``triangle``       3.1.3  apex on the plane: the triangle of eqs (14)–(17), not a point;
- ``base_chord``     3.1.4  close parabolas and hyperbolas with the base points of eq. (17);
- ``vo_lines``       3.1.5  VOlineL / VOlineR bound the removed part of the protected zone;
- ``virtual_sphere`` 3.1.6  applied when the cone is built (``vo_cones``), listed for completeness.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .cone import VOCones
from .frames import AvoidancePlanes
from .pyramid import BOX_EDGES, VOPyramids

KINDS = ("blank", "point", "line", "triangle", "circle", "ellipse", "parabola", "hyperbola")
#: Beyond the paper's eight kinds: A is inside the protected zone, the VO is a half-plane.
INSIDE = "inside"
KIND_NAMES = np.array(KINDS + (INSIDE,))
BLANK, POINT, LINE, TRIANGLE, CIRCLE, ELLIPSE, PARABOLA, HYPERBOLA, INSIDE_CODE = range(9)

CORRECTIONS = frozenset(
    {"tg_range", "symmetry_abs", "triangle", "base_chord", "vo_lines", "virtual_sphere"}
)

#: Default number of generator samples t in [0, 2 pi) for the curve of eq. (12).
N_SAMPLES = 72
_ANGLE_TOL = 1e-7


@dataclass(frozen=True)
class Sections:
    """Sections of n VO shapes on P planes. Arrays are (n, P, ...); NaN marks 'none'."""

    kind: np.ndarray  # (n, P) codes into KIND_NAMES
    vertices: np.ndarray  # (n, P, V, 2) candidate polygon vertices ...
    vertex_mask: np.ndarray  # (n, P, V) ... and which of them are used
    apex: np.ndarray  # (n, P, 2) A^phi projected on the plane
    chord: np.ndarray  # (n, P, 2, 2) base points of eq. (17)
    symmetry: np.ndarray  # (n, P, 2) H of eq. (13)
    halfplane: np.ndarray  # (n, P, 3) inside-zone VO: a x + b y > c
    vo_lines: bool
    curve: np.ndarray  # (n, P, K, 2) points of eq. (12) kept as vertices (NaN otherwise)
    t: np.ndarray  # (K,) generator angles of the curve samples
    chord_t: np.ndarray  # (n, P, 2) generator angles of the chord points (NaN when none)

    @property
    def kind_names(self) -> np.ndarray:
        return KIND_NAMES[self.kind]

    @cached_property
    def polygon(self) -> np.ndarray:
        """(n, P, V, 2) the section's polygon, vertices in angular order, padded with NaN
        (all NaN when degenerate). Built on first use: the QPs need only the boundary points."""
        poly = _angular_order(self.vertices, self.vertex_mask)
        return np.where((_polygon_area(poly) > 1e-14)[..., None, None], poly, np.nan)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Whether in-plane points lie inside each section: xy (P, M, 2) -> (n, P, M)."""
        xy = np.asarray(xy, dtype=float)
        inside = _in_polygon(self.polygon, xy)
        if self.vo_lines:
            inside |= _beyond_chord(self.polygon, self.apex, self.chord, xy)
        # The VO is open at its apex: zero relative velocity never collides (e.g. hovering
        # beside a static obstacle), although the apex is a vertex of the triangle.
        at_apex = np.linalg.norm(xy[None] - self.apex[:, :, None, :], axis=-1) <= 1e-9
        inside &= ~(at_apex & (self.kind == TRIANGLE)[..., None])
        hp = self.halfplane
        in_half = hp[..., None, 0] * xy[None, ..., 0] + hp[..., None, 1] * xy[None, ..., 1] > hp[..., None, 2]
        return np.where((self.kind == INSIDE_CODE)[..., None], in_half, inside)


def _in_polygon(poly: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Even-odd crossing test of points (P, M, 2) in polygons (n, P, V, 2) padded with NaN."""
    a = poly
    b = np.roll(poly, -1, axis=2)
    # Close each polygon: the edge leaving the last real vertex goes back to the first one.
    last = np.isnan(b[..., 0]) & ~np.isnan(a[..., 0])
    b = np.where(last[..., None], poly[:, :, :1, :], b)
    ax, ay = a[..., None, 0], a[..., None, 1]  # (n, P, V, 1)
    bx, by = b[..., None, 0], b[..., None, 1]
    px, py = xy[None, :, None, :, 0], xy[None, :, None, :, 1]  # (1, P, 1, M)
    with np.errstate(invalid="ignore", divide="ignore"):
        straddle = (ay > py) != (by > py)
        x_cross = ax + (py - ay) * (bx - ax) / (by - ay)
        hits = straddle & (px < x_cross)
    return (np.sum(hits, axis=2) % 2) == 1


def _nanmean(a: np.ndarray, axis: int, keepdims: bool = False) -> np.ndarray:
    """Mean over ``axis`` ignoring NaN; NaN where every entry is NaN (without a warning)."""
    count = np.sum(~np.isnan(a), axis=axis, keepdims=keepdims)
    total = np.nansum(a, axis=axis, keepdims=keepdims)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _beyond_chord(poly: np.ndarray, apex: np.ndarray, chord: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Section 3.1.5: points beyond the chord P1P2 and between VOlineL and VOlineR, the rays from
    P1 and P2 pointing away from the projected apex. (n, P, M)."""
    p1, p2 = chord[:, :, 0, :], chord[:, :, 1, :]
    ref = _nanmean(poly, axis=2)  # a point of the section on the near side of the chord
    ref = np.where(np.isnan(ref), apex, ref)
    q = xy[None]  # (1, P, M, 2)
    e = p2 - p1
    s_ref = _cross(e, ref - p1)[..., None]
    s_q = _cross(e[:, :, None], q - p1[:, :, None])
    beyond = s_q * s_ref < 0
    d1, d2 = p1 - apex, p2 - apex
    in1 = _cross(d1, p2 - p1)[..., None] * _cross(d1[:, :, None], q - p1[:, :, None]) >= 0
    in2 = _cross(d2, p1 - p2)[..., None] * _cross(d2[:, :, None], q - p2[:, :, None]) >= 0
    ok = np.all(np.isfinite(chord), axis=(2, 3)) & (np.linalg.norm(e, axis=-1) > 1e-12)
    return beyond & in1 & in2 & ok[..., None]


def _angular_order(points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Sort candidate vertices (n, P, V, 2) by angle about their mean; invalid ones -> NaN at
    the end. For a convex section this is the boundary order."""
    pts = np.where(valid[..., None], points, np.nan)
    center = _nanmean(pts, axis=2, keepdims=True)
    ang = np.arctan2(pts[..., 1] - center[..., 1], pts[..., 0] - center[..., 0])
    ang = np.where(valid, ang, np.inf)
    order = np.argsort(ang, axis=2)
    return np.take_along_axis(pts, order[..., None], axis=2)


def _polygon_area(poly: np.ndarray) -> np.ndarray:
    p = np.nan_to_num(poly)
    nxt = np.roll(poly, -1, axis=2)
    nxt = np.where(np.isnan(nxt), poly[:, :, :1, :], nxt)
    return 0.5 * np.abs(np.sum(_cross(p, np.nan_to_num(nxt)), axis=2))


def base_circle_crossings(cones: VOCones, planes: AvoidancePlanes) -> tuple[np.ndarray, np.ndarray]:
    """Eqs (14)–(16): the angles t1, t2 at which the base circle B_vo meets each plane, (n, P)
    each (NaN when it does not). z^phi of B_vo(t) is A' + B' cos t + C' sin t = 0."""
    n_w = planes.normal  # (P, 3)
    R = cones.R
    z_apex = cones.apex @ n_w.T  # (n, P)
    A_ = z_apex + cones.d_vo[:, None] * (R[:, :, 0] @ n_w.T)
    B_ = cones.r_vo[:, None] * (R[:, :, 1] @ n_w.T)
    C_ = cones.r_vo[:, None] * (R[:, :, 2] @ n_w.T)
    rho = np.hypot(B_, C_)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = -A_ / rho
    ok = (np.abs(ratio) <= 1.0) & (rho > 0)
    base = np.arctan2(C_, B_)
    delta = np.arccos(np.clip(ratio, -1.0, 1.0))
    t1 = np.where(ok, base - delta, np.nan)
    t2 = np.where(ok, base + delta, np.nan)
    return t1, t2


def cone_sections(
    cones: VOCones,
    planes: AvoidancePlanes,
    *,
    corrections: frozenset[str] | set[str] = CORRECTIONS,
    n_samples: int = N_SAMPLES,
) -> Sections:
    """The conic sections of ``cones`` on ``planes`` (section 3.1), classified into KINDS."""
    unknown = set(corrections) - CORRECTIONS
    if unknown:
        raise ValueError(f"corrections: unknown {sorted(unknown)}; known {sorted(CORRECTIONS)}")
    n, P = len(cones), len(planes.phi)
    t = np.linspace(0.0, 2.0 * np.pi, n_samples, endpoint=False)
    A_phi = planes.coords(cones.apex)  # eq. (7), (n, P, 3)
    B_phi = planes.coords(cones.base_points(t))  # eq. (9), (n, P, K, 3)
    C_phi = planes.coords(cones.center)
    zA = A_phi[..., 2]
    scale = 1.0 + np.linalg.norm(cones.apex, axis=1)[:, None] + cones.d_vo[:, None]
    on_apex = np.abs(zA) <= 1e-9 * scale  # section 3.1.3: A_vo lies on the plane

    # Eqs (11)–(12): generator t meets the plane at parameter t_g.
    dz = B_phi[..., 2] - zA[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_g = -zA[..., None] / dz
    if "tg_range" in corrections:  # 3.1.1
        valid = (t_g >= 0.0) & (t_g <= 1.0)
    else:  # the original condition z_Bvo != z_A: both nappes, any length
        valid = np.isfinite(t_g) & (np.abs(dz) > 1e-12)
    with np.errstate(invalid="ignore"):  # t_g is inf/NaN where unused: masked by ``valid``
        curve = (B_phi[..., :2] - A_phi[:, :, None, :2]) * t_g[..., None] + A_phi[:, :, None, :2]

    # Eqs (14)–(17): where the base circle meets the plane.
    t1, t2 = base_circle_crossings(cones, planes)
    chord_t = np.stack([t1, t2], axis=-1)  # (n, P, 2)
    chord_ok = np.all(np.isfinite(chord_t), axis=-1)
    chord_pts = _base_points_on_planes(cones, planes, np.nan_to_num(chord_t))
    chord_pts = np.where(chord_ok[..., None, None], chord_pts, np.nan)

    # Classification by the angle between the plane and the axis (|n·a| vs sin alpha).
    na = np.abs(cones.axis @ planes.normal.T)  # (n, P)
    sa = cones.sin_alpha[:, None]
    cut_any = np.any(valid, axis=-1) | chord_ok
    kind = np.full((n, P), BLANK)
    kind = np.where(na > sa + _ANGLE_TOL, np.where(na > 1 - _ANGLE_TOL, CIRCLE, ELLIPSE), kind)
    kind = np.where(np.abs(na - sa) <= _ANGLE_TOL, PARABOLA, kind)
    kind = np.where(na < sa - _ANGLE_TOL, HYPERBOLA, kind)
    kind = np.where(cut_any, kind, BLANK)
    apex_kind = np.where(na > sa + _ANGLE_TOL, POINT, np.where(na >= sa - _ANGLE_TOL, LINE, TRIANGLE))
    if "triangle" not in corrections:  # the original reduces eq. (12) to the single point A^phi
        apex_kind = np.where(apex_kind == TRIANGLE, POINT, apex_kind)
    kind = np.where(on_apex, apex_kind, kind)

    # Polygon vertices: curve points, chord points (3.1.4), and the apex for triangles (3.1.3).
    use_curve = valid & ~on_apex[..., None]
    use_chord = np.broadcast_to(chord_ok[..., None], chord_ok.shape + (2,)).copy()
    if "base_chord" not in corrections:
        use_chord &= on_apex[..., None]  # the triangle's own two points (eq. 17) stay
    use_chord &= (kind != POINT)[..., None]
    use_apex = (kind == TRIANGLE)[..., None]
    pts = np.concatenate([curve, np.nan_to_num(chord_pts), A_phi[:, :, None, :2]], axis=2)
    mask = np.concatenate([use_curve, use_chord, use_apex], axis=2)

    # Eq. (13): the symmetry-line point H.
    dzc = C_phi[..., 2] - zA
    with np.errstate(divide="ignore", invalid="ignore"):
        t_h = -zA / dzc
    if "symmetry_abs" in corrections:
        t_h = np.abs(t_h)
    parallel = np.abs(dzc) <= 1e-12 * scale
    with np.errstate(invalid="ignore"):  # t_h undefined when parallel: replaced just below
        H = (C_phi[..., :2] - A_phi[..., :2]) * t_h[..., None] + A_phi[..., :2]
    H = np.where(parallel[..., None], C_phi[..., :2], H)

    # Inside the protected zone: the VO is the closing half-space (v - apex)·rel > 0.
    rel_p = planes.coords(cones.rel)
    halfplane = np.concatenate([rel_p[..., :2], (A_phi * rel_p).sum(-1, keepdims=True)], axis=-1)
    kind = np.where(cones.inside[:, None], INSIDE_CODE, kind)

    return Sections(
        kind=kind, vertices=pts, vertex_mask=mask, apex=A_phi[..., :2], chord=chord_pts, symmetry=H,
        halfplane=halfplane, vo_lines="vo_lines" in corrections,
        curve=np.where(use_curve[..., None], curve, np.nan), t=t, chord_t=chord_t,
    )


def _base_points_on_planes(cones: VOCones, planes: AvoidancePlanes, t: np.ndarray) -> np.ndarray:
    """B_vo(t) in plane coordinates for per-(cone, plane) angles t (n, P, k) -> (n, P, k, 2)."""
    body = np.stack(
        [np.broadcast_to(cones.d_vo[:, None, None], t.shape),
         cones.r_vo[:, None, None] * np.cos(t), cones.r_vo[:, None, None] * np.sin(t)],
        axis=-1,
    )
    world = body @ cones.R[:, None].transpose(0, 1, 3, 2) + cones.apex[:, None, None, :]
    # Each plane's own points: rotate about the common axis with that plane's phi.
    f = world @ planes.frame.T
    c, s = np.cos(planes.phi)[None, :, None], np.sin(planes.phi)[None, :, None]
    return np.stack([f[..., 0], c * f[..., 1] + s * f[..., 2]], axis=-1)


def pyramid_sections(pyramids: VOPyramids, planes: AvoidancePlanes) -> Sections:
    """Sections of VO pyramids (section 4.2). Every avoidance plane contains the apex (the
    velocity origin, eq. 19), so a section is a triangle (apex and the two extreme points where
    C_pz's edges meet the plane; with the VO lines, the whole wedge), a line, or the apex point."""
    m, P = len(pyramids), len(planes.phi)
    corners = planes.coords(pyramids.corners)  # (m, P, 8, 3)
    za = corners[:, :, BOX_EDGES[:, 0], 2]
    zb = corners[:, :, BOX_EDGES[:, 1], 2]
    pa = corners[:, :, BOX_EDGES[:, 0], :2]
    pb = corners[:, :, BOX_EDGES[:, 1], :2]
    crosses = (za * zb <= 0) & (za != zb)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = za / (za - zb)
    with np.errstate(invalid="ignore"):  # an edge lying in the plane: masked by ``crosses``
        pts = pa + s[..., None] * (pb - pa)  # (m, P, 12, 2): C_pz ∩ plane is their convex hull
    pts = np.where(crosses[..., None], pts, np.nan)
    unit = pts / np.linalg.norm(pts, axis=-1, keepdims=True)
    mean_dir = _nanmean(unit, axis=2)
    ang = np.arctan2(_cross(mean_dir[:, :, None], unit), np.einsum("mpi,mpki->mpk", mean_dir, unit))
    any_cross = np.any(crosses, axis=-1)
    lo = np.argmin(np.where(crosses, ang, np.inf), axis=-1)
    hi = np.argmax(np.where(crosses, ang, -np.inf), axis=-1)
    p1 = np.take_along_axis(pts, lo[..., None, None], axis=2)[:, :, 0]
    p2 = np.take_along_axis(pts, hi[..., None, None], axis=2)[:, :, 0]
    width = np.take_along_axis(ang, hi[..., None], -1)[..., 0] - np.take_along_axis(ang, lo[..., None], -1)[..., 0]
    kind = np.where(any_cross, np.where(width > 1e-9, TRIANGLE, LINE), POINT)
    chord = np.where((kind == TRIANGLE)[..., None, None], np.stack([p1, p2], axis=2), np.nan)
    apex = np.zeros((m, P, 2))
    vertices = np.concatenate([apex[:, :, None, :], np.nan_to_num(chord)], axis=2)
    vertex_mask = np.broadcast_to((kind == TRIANGLE)[..., None], vertices.shape[:3])
    # Inside C_pz: the VO is every velocity with a horizontal component towards its centre.
    h_p = planes.coords(pyramids.frame[:, 0, :])
    halfplane = np.concatenate([h_p[..., :2], np.zeros((m, P, 1))], axis=-1)
    kind = np.where(pyramids.inside[:, None], INSIDE_CODE, kind)
    symmetry = np.where(any_cross[..., None], _nanmean(pts, axis=2), np.nan)
    return Sections(
        kind=kind, vertices=vertices, vertex_mask=vertex_mask, apex=apex, chord=chord, symmetry=symmetry,
        halfplane=halfplane, vo_lines=True,
        curve=np.full((m, P, 0, 2), np.nan), t=np.zeros(0), chord_t=np.full((m, P, 2), np.nan),
    )
