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

import functools
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .._jit import jit
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


@functools.lru_cache(maxsize=16)
def generator_angles(n_samples: int) -> np.ndarray:
    """The generator angles t of eq. (12): n_samples in [0, 2 pi) (read-only)."""
    t = np.linspace(0.0, 2.0 * np.pi, n_samples, endpoint=False)
    t.setflags(write=False)
    return t


@jit
def _crossings(apex, R, d_vo, r_vo, nx, ny, nz):
    """Eqs (14)–(16) for one cone and the plane with normal n: (t1, t2), NaN when B_vo misses it."""
    A_ = d_vo * (R[0, 0] * nx + R[1, 0] * ny + R[2, 0] * nz) + apex[0] * nx + apex[1] * ny + apex[2] * nz
    B_ = r_vo * (R[0, 1] * nx + R[1, 1] * ny + R[2, 1] * nz)
    C_ = r_vo * (R[0, 2] * nx + R[1, 2] * ny + R[2, 2] * nz)
    rho = np.hypot(B_, C_)
    ratio = -A_ / rho
    if abs(ratio) <= 1.0 and rho > 0:
        base, delta = np.arctan2(C_, B_), np.arccos(min(max(ratio, -1.0), 1.0))
        return base - delta, base + delta
    return np.nan, np.nan


@jit
def _to_plane(v, frame, c, s):
    """Eq. (8): world vector -> (x^phi, y^phi, z^phi) on the plane with cos/sin phi = c, s."""
    f0 = frame[0, 0] * v[0] + frame[0, 1] * v[1] + frame[0, 2] * v[2]
    f1 = frame[1, 0] * v[0] + frame[1, 1] * v[1] + frame[1, 2] * v[2]
    f2 = frame[2, 0] * v[0] + frame[2, 1] * v[1] + frame[2, 2] * v[2]
    return f0, c * f1 + s * f2, c * f2 - s * f1


@jit
def _base_point(apex, R, d_vo, r_vo, t, out):
    """B_vo(t) of eq. (4) in the world frame, written into ``out`` (3,)."""
    ct, st = r_vo * np.cos(t), r_vo * np.sin(t)
    for k in range(3):
        out[k] = apex[k] + R[k, 0] * d_vo + R[k, 1] * ct + R[k, 2] * st


@jit
def cone_section_arrays(apex, R, d_vo, r_vo, sin_alpha, rel, inside, frame, phi, t,
                          tg_range, symmetry_abs, triangle, base_chord):
    """Section 3.1 one cone and one plane at a time (see cone_sections for the outputs)."""
    n, P, K = apex.shape[0], phi.shape[0], t.shape[0]
    kind = np.full((n, P), BLANK, dtype=np.int64)
    pts = np.full((n, P, K + 3, 2), np.nan)
    mask = np.zeros((n, P, K + 3), dtype=np.bool_)
    apex_xy = np.empty((n, P, 2))
    chord = np.full((n, P, 2, 2), np.nan)
    chord_t = np.full((n, P, 2), np.nan)
    H = np.empty((n, P, 2))
    halfplane = np.empty((n, P, 3))
    curve = np.full((n, P, K, 2), np.nan)
    cphi, sphi = np.cos(phi), np.sin(phi)
    B_world, B_f, B_chord, C_world = np.empty((K, 3)), np.empty((K, 3)), np.empty(3), np.empty(3)
    for i in range(n):
        for k in range(K):
            _base_point(apex[i], R[i], d_vo[i], r_vo[i], t[k], B_world[k])  # eq. (9) before eq. (8)
            # in the (e_x, e_y0, e_z0) frame once: each plane then only turns about e_x
            B_f[k, 0], B_f[k, 1], B_f[k, 2] = _to_plane(B_world[k], frame, 1.0, 0.0)
        for k in range(3):
            C_world[k] = apex[i, k] + d_vo[i] * R[i, k, 0]  # C_vo, eq. (5)
        a_norm = np.sqrt(apex[i, 0] ** 2 + apex[i, 1] ** 2 + apex[i, 2] ** 2)
        scale = 1.0 + a_norm + d_vo[i]
        sa = sin_alpha[i]
        for p in range(P):
            c, s = cphi[p], sphi[p]
            xA, yA, zA = _to_plane(apex[i], frame, c, s)  # eq. (7)
            apex_xy[i, p, 0], apex_xy[i, p, 1] = xA, yA
            on_apex = abs(zA) <= 1e-9 * scale  # section 3.1.3: A_vo lies on the plane
            # Eqs (11)-(12): generator k meets the plane at parameter t_g.
            any_valid = False
            for k in range(K):
                xB, yB, zB = B_f[k, 0], c * B_f[k, 1] + s * B_f[k, 2], c * B_f[k, 2] - s * B_f[k, 1]
                dz = zB - zA
                t_g = -zA / dz
                if tg_range:  # 3.1.1
                    valid = t_g >= 0.0 and t_g <= 1.0
                else:  # the original condition z_Bvo != z_A: both nappes, any length
                    valid = np.isfinite(t_g) and abs(dz) > 1e-12
                x, y = (xB - xA) * t_g + xA, (yB - yA) * t_g + yA
                pts[i, p, k, 0], pts[i, p, k, 1] = x, y
                if valid:
                    any_valid = True
                    if not on_apex:
                        mask[i, p, k] = True
                        curve[i, p, k, 0], curve[i, p, k, 1] = x, y
            # Eqs (14)-(17): where the base circle meets the plane.
            nx, ny, nz = (c * frame[2, 0] - s * frame[1, 0], c * frame[2, 1] - s * frame[1, 1],
                          c * frame[2, 2] - s * frame[1, 2])
            t1, t2 = _crossings(apex[i], R[i], d_vo[i], r_vo[i], nx, ny, nz)
            chord_ok = np.isfinite(t1) and np.isfinite(t2)
            for j in range(2):
                if chord_ok:
                    chord_t[i, p, j] = t1 if j == 0 else t2
                    _base_point(apex[i], R[i], d_vo[i], r_vo[i], chord_t[i, p, j], B_chord)
                    x, y, _ = _to_plane(B_chord, frame, c, s)
                    chord[i, p, j, 0], chord[i, p, j, 1] = x, y
                    pts[i, p, K + j, 0], pts[i, p, K + j, 1] = x, y
                else:
                    pts[i, p, K + j, 0], pts[i, p, K + j, 1] = 0.0, 0.0
            pts[i, p, K + 2, 0], pts[i, p, K + 2, 1] = xA, yA
            # Classification by the angle between the plane and the axis (|n·a| vs sin alpha).
            na = abs(R[i, 0, 0] * nx + R[i, 1, 0] * ny + R[i, 2, 0] * nz)
            kd = BLANK
            if any_valid or chord_ok:
                if na > sa + _ANGLE_TOL:
                    kd = CIRCLE if na > 1 - _ANGLE_TOL else ELLIPSE
                elif abs(na - sa) <= _ANGLE_TOL:
                    kd = PARABOLA
                elif na < sa - _ANGLE_TOL:
                    kd = HYPERBOLA
            if on_apex:
                kd = POINT if na > sa + _ANGLE_TOL else (LINE if na >= sa - _ANGLE_TOL else TRIANGLE)
                if kd == TRIANGLE and not triangle:  # the original reduces eq. (12) to A^phi
                    kd = POINT
            # Polygon vertices: chord points (3.1.4), and the apex for triangles (3.1.3).
            use_chord = chord_ok and (base_chord or on_apex) and kd != POINT
            mask[i, p, K] = mask[i, p, K + 1] = use_chord
            mask[i, p, K + 2] = kd == TRIANGLE
            # Eq. (13): the symmetry-line point H.
            xC, yC, zC = _to_plane(C_world, frame, c, s)
            dzc = zC - zA
            if abs(dzc) <= 1e-12 * scale:  # the axis is parallel to the plane
                H[i, p, 0], H[i, p, 1] = xC, yC
            else:
                t_h = -zA / dzc
                if symmetry_abs:
                    t_h = abs(t_h)
                H[i, p, 0], H[i, p, 1] = (xC - xA) * t_h + xA, (yC - yA) * t_h + yA
            # Inside the protected zone: the VO is the closing half-space (v - apex)·rel > 0.
            xr, yr, zr = _to_plane(rel[i], frame, c, s)
            halfplane[i, p, 0], halfplane[i, p, 1] = xr, yr
            halfplane[i, p, 2] = xA * xr + yA * yr + zA * zr
            kind[i, p] = INSIDE_CODE if inside[i] else kd
    return kind, pts, mask, apex_xy, chord, chord_t, H, halfplane, curve


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
    t = generator_angles(n_samples)
    kind, pts, mask, apex, chord, chord_t, H, halfplane, curve = cone_section_arrays(
        cones.apex, cones.R, cones.d_vo, cones.r_vo, cones.sin_alpha, cones.rel, cones.inside,
        planes.frame, planes.phi, t, "tg_range" in corrections, "symmetry_abs" in corrections,
        "triangle" in corrections, "base_chord" in corrections)
    return Sections(
        kind=kind, vertices=pts, vertex_mask=mask, apex=apex, chord=chord, symmetry=H,
        halfplane=halfplane, vo_lines="vo_lines" in corrections, curve=curve, t=t, chord_t=chord_t,
    )


@jit
def pyramid_section_arrays(corners, edges, h_dir, inside, frame, phi):
    """Section 4.2 one pyramid and one plane at a time (see pyramid_sections)."""
    m, P, E = corners.shape[0], phi.shape[0], edges.shape[0]
    kind = np.full((m, P), POINT, dtype=np.int64)
    chord = np.full((m, P, 2, 2), np.nan)
    symmetry = np.full((m, P, 2), np.nan)
    halfplane = np.zeros((m, P, 3))
    pts = np.empty((E, 2))
    unit = np.empty((E, 2))
    crosses = np.zeros(E, dtype=np.bool_)
    cphi, sphi = np.cos(phi), np.sin(phi)
    local = np.empty((8, 3))
    for j in range(m):
        for p in range(P):
            c, s = cphi[p], sphi[p]
            for k in range(8):
                local[k, 0], local[k, 1], local[k, 2] = _to_plane(corners[j, k], frame, c, s)
            # C_pz ∩ plane is the convex hull of the points where its edges cross the plane.
            count, mx, my, sx, sy = 0, 0.0, 0.0, 0.0, 0.0
            for e in range(E):
                a, b = edges[e, 0], edges[e, 1]
                za, zb = local[a, 2], local[b, 2]
                crosses[e] = za * zb <= 0 and za != zb
                if crosses[e]:
                    f = za / (za - zb)
                    pts[e, 0] = local[a, 0] + f * (local[b, 0] - local[a, 0])
                    pts[e, 1] = local[a, 1] + f * (local[b, 1] - local[a, 1])
                    norm = np.hypot(pts[e, 0], pts[e, 1])
                    unit[e, 0], unit[e, 1] = pts[e, 0] / norm, pts[e, 1] / norm
                    sx, sy = sx + pts[e, 0], sy + pts[e, 1]
                    if norm > 0:
                        mx, my, count = mx + unit[e, 0], my + unit[e, 1], count + 1
            xh, yh, _ = _to_plane(h_dir[j], frame, c, s)
            halfplane[j, p, 0], halfplane[j, p, 1] = xh, yh
            n_cross = np.sum(crosses)
            if n_cross == 0:
                kind[j, p] = INSIDE_CODE if inside[j] else POINT
                continue
            symmetry[j, p, 0], symmetry[j, p, 1] = sx / n_cross, sy / n_cross
            # The extreme crossing points seen from the apex (the velocity origin, eq. 19).
            if count:
                mx, my = mx / count, my / count
            lo, hi, a_lo, a_hi, at_apex = -1, -1, np.inf, -np.inf, False
            for e in range(E):
                if crosses[e]:
                    ang = np.arctan2(mx * unit[e, 1] - my * unit[e, 0], mx * unit[e, 0] + my * unit[e, 1])
                    at_apex |= np.isnan(ang)  # A on the surface of C_pz: no wedge to speak of
                    if ang < a_lo:
                        lo, a_lo = e, ang
                    if ang > a_hi:
                        hi, a_hi = e, ang
            if not at_apex and a_hi - a_lo > 1e-9:
                kind[j, p] = TRIANGLE
                chord[j, p, 0, 0], chord[j, p, 0, 1] = pts[lo, 0], pts[lo, 1]
                chord[j, p, 1, 0], chord[j, p, 1, 1] = pts[hi, 0], pts[hi, 1]
            else:
                kind[j, p] = LINE
            if inside[j]:
                kind[j, p] = INSIDE_CODE
    return kind, chord, symmetry, halfplane


def pyramid_sections(pyramids: VOPyramids, planes: AvoidancePlanes) -> Sections:
    """Sections of VO pyramids (section 4.2). Every avoidance plane contains the apex (the
    velocity origin, eq. 19), so a section is a triangle (apex and the two extreme points where
    C_pz's edges meet the plane; with the VO lines, the whole wedge), a line, or the apex point.
    Inside C_pz the VO is every velocity with a horizontal component towards its centre."""
    m, P = len(pyramids), len(planes.phi)
    kind, chord, symmetry, halfplane = pyramid_section_arrays(
        pyramids.corners, BOX_EDGES, np.ascontiguousarray(pyramids.frame[:, 0, :]), pyramids.inside,
        planes.frame, planes.phi)
    vertices = np.zeros((m, P, 3, 2))
    vertices[:, :, 1:] = np.nan_to_num(chord)
    triangle = np.isfinite(chord[:, :, 0, 0])
    return Sections(
        kind=kind, vertices=vertices, vertex_mask=np.broadcast_to(triangle[..., None], (m, P, 3)),
        apex=np.zeros((m, P, 2)), chord=chord, symmetry=symmetry, halfplane=halfplane, vo_lines=True,
        curve=np.full((m, P, 0, 2), np.nan), t=np.zeros(0), chord_t=np.full((m, P, 2), np.nan),
    )
