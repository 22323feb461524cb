"""Conic sections of VO cones and VO pyramids on the avoidance planes (sections 3.1 and 4.2).

Every section is described the paper's way, in plane coordinates (x^phi, y^phi): the curve of
eq. (12) (generators of the cone meeting the plane), the two points of eq. (17) where the base
circle B_vo meets it (the "chord"), the projected apex A^phi, the symmetry-line point H of
eq. (13), and the VOlineL / VOlineR rays of section 3.1.5. ``cone_section`` and
``pyramid_section`` compute one shape on one plane (compiled; the decision kernel calls them
directly); ``cone_sections`` / ``pyramid_sections`` fill all shapes on all planes, and
``Sections.contains`` says whether in-plane velocities lie inside: inside the polygon through the
curve and chord points (or the triangle), or between the VO lines beyond the chord.

The six corrections of section 3.1 can be switched off one by one (``Corrections``) to show
what the original formulas of Jenie et al. get wrong; the default applies all of them:

- ``tg_range``       3.1.1  keep curve points with 0 <= t_g <= 1 only (no spurious branch);
- ``symmetry_abs``   3.1.2  H uses |t_h| (no error side, any plane cutting the axis line);
- ``triangle``       3.1.3  apex on the plane: the triangle of eqs (14)–(17), not a point;
- ``base_chord``     3.1.4  close parabolas and hyperbolas with the base points of eq. (17);
- ``vo_lines``       3.1.5  VOlineL / VOlineR bound the removed part of the protected zone;
- ``virtual_sphere`` 3.1.6  applied when the cone is built (``vo_cones``), listed for completeness.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from .._jit import entry, inline, jit, kernel
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


class Corrections(NamedTuple):
    """Which of the six corrections of section 3.1 apply (all by default)."""

    tg_range: bool = True
    symmetry_abs: bool = True
    triangle: bool = True
    base_chord: bool = True
    vo_lines: bool = True
    virtual_sphere: bool = True

    @classmethod
    def of(cls, names: Iterable[str] | None) -> Corrections:
        """From a set of correction names (None: all); ValueError for an unknown name."""
        if names is None:
            return cls()
        names = set(names)
        if unknown := names - CORRECTIONS:
            raise ValueError(f"corrections: unknown {sorted(unknown)}; known {sorted(CORRECTIONS)}")
        return cls(*(field in names for field in cls._fields))


class Section(NamedTuple):
    """One VO shape on one avoidance plane, in plane coordinates (NaN where there is none).
    The arrays are written by ``cone_section`` / ``pyramid_section``."""

    # (2, K) eq. (12): x and y where generator k meets the plane (a vertex), else NaN
    curve: np.ndarray
    chord: np.ndarray  # (2, 2) eq. (17): B_vo meets the plane here
    chord_cs: np.ndarray  # (2, 2) cos and sin of the generator angles of the chord points
    apex: np.ndarray  # (2,) A^phi of eq. (7)
    symmetry: np.ndarray  # (2,) H of eq. (13)
    halfplane: np.ndarray  # (3,) A inside the zone: the VO is a x + b y > c


@functools.lru_cache(maxsize=16)
def generator_angles(n_samples: int) -> np.ndarray:
    """The generator angles t of eq. (12): n_samples in [0, 2 pi) (read-only)."""
    t = np.linspace(0.0, 2.0 * np.pi, n_samples, endpoint=False)
    t.setflags(write=False)
    return t


@inline
def _crossings(apex, R, d_vo, r_vo, nx, ny, nz, cs):
    """Eqs (14)–(16) for one cone and the plane with normal n: B_vo(t) meets it where
    A + B cos t + C sin t = 0; the two roots' (cos t, sin t) into ``cs`` (2, 2), solved without
    trigonometry. False when the base circle misses the plane."""
    A_ = (
        d_vo * (R[0, 0] * nx + R[1, 0] * ny + R[2, 0] * nz)
        + apex[0] * nx
        + apex[1] * ny
        + apex[2] * nz
    )
    B_ = r_vo * (R[0, 1] * nx + R[1, 1] * ny + R[2, 1] * nz)
    C_ = r_vo * (R[0, 2] * nx + R[1, 2] * ny + R[2, 2] * nz)
    rho2 = B_ * B_ + C_ * C_
    if not (rho2 > 0 and A_ * A_ <= rho2):
        return False
    root = np.sqrt(rho2 - A_ * A_)
    for j in range(
        2
    ):  # (cos, sin) = (-A (B, C) -/+ root (C, -B)) / rho²: t = atan2(C, B) -/+ acos(-A/rho)
        sign = -1.0 if j == 0 else 1.0
        cs[j, 0] = (-A_ * B_ - sign * root * C_) / rho2
        cs[j, 1] = (-A_ * C_ + sign * root * B_) / rho2
    return True


@inline
def _framed(x, y, z, frame):
    """A world vector in the planes' (e_x, e_y0, e_z0) frame: every plane then only turns it
    about e_x (eq. 8)."""
    return (
        frame[0, 0] * x + frame[0, 1] * y + frame[0, 2] * z,
        frame[1, 0] * x + frame[1, 1] * y + frame[1, 2] * z,
        frame[2, 0] * x + frame[2, 1] * y + frame[2, 2] * z,
    )


@kernel
def cone_base_points(
    cones: VOCones, i: int, frame: np.ndarray, cos_t: np.ndarray, sin_t: np.ndarray, out: np.ndarray
) -> None:
    """B_vo(t_k) of eq. (4) for every generator angle, in the planes' (e_x, e_y0, e_z0) frame,
    into ``out`` (3, K + 3), one row per axis (so that the per-plane loop vectorises); its last
    three columns are the apex, C_vo (eq. 5) and rel."""
    a, R, dv, rv = cones.apex[i], cones.R[i], cones.d_vo[i], cones.r_vo[i]
    K = cos_t.shape[0]
    for k in range(K):
        ct, st = rv * cos_t[k], rv * sin_t[k]
        out[0, k], out[1, k], out[2, k] = _framed(
            a[0] + R[0, 0] * dv + R[0, 1] * ct + R[0, 2] * st,
            a[1] + R[1, 0] * dv + R[1, 1] * ct + R[1, 2] * st,
            a[2] + R[2, 0] * dv + R[2, 1] * ct + R[2, 2] * st,
            frame,
        )
    out[0, K], out[1, K], out[2, K] = _framed(a[0], a[1], a[2], frame)
    out[0, K + 1], out[1, K + 1], out[2, K + 1] = _framed(
        a[0] + dv * R[0, 0], a[1] + dv * R[1, 0], a[2] + dv * R[2, 0], frame
    )
    rel = cones.rel[i]
    out[0, K + 2], out[1, K + 2], out[2, K + 2] = _framed(rel[0], rel[1], rel[2], frame)


@inline
def cone_section(
    cones: VOCones,
    i: int,
    base: np.ndarray,
    frame: np.ndarray,
    c: float,
    s: float,
    corr: Corrections,
    sec: Section,
) -> int:
    """Section 3.1 for cone i on the plane with cos/sin phi = c, s: writes ``sec`` and returns
    the kind. ``base`` is ``cone_base_points`` of the cone."""
    K = base.shape[1] - 3
    apex, R, d_vo, r_vo = cones.apex[i], cones.R[i], cones.d_vo[i], cones.r_vo[i]
    # eq. (7)
    xA, yA, zA = base[0, K], c * base[1, K] + s * base[2, K], c * base[2, K] - s * base[1, K]
    sec.apex[0], sec.apex[1] = xA, yA
    scale = 1.0 + np.sqrt(apex[0] ** 2 + apex[1] ** 2 + apex[2] ** 2) + d_vo
    on_apex = abs(zA) <= 1e-9 * scale  # section 3.1.3: A_vo lies on the plane
    # Eqs (11)-(12): generator k meets the plane at parameter t_g. Written without branches
    # (bitwise & on booleans, selects) so that the compiler can vectorise it.
    any_valid, nan = False, np.nan
    for k in range(K):
        yB, zB = c * base[1, k] + s * base[2, k], c * base[2, k] - s * base[1, k]
        dz = zB - zA
        t_g = -zA / dz
        if corr.tg_range:  # 3.1.1
            valid = (t_g >= 0.0) & (t_g <= 1.0)
        else:  # the original condition z_Bvo != z_A: both nappes, any length
            valid = np.isfinite(t_g) & (abs(dz) > 1e-12)
        any_valid |= valid
        keep = valid & (not on_apex)
        sec.curve[0, k] = (base[0, k] - xA) * t_g + xA if keep else nan
        sec.curve[1, k] = (yB - yA) * t_g + yA if keep else nan
    # Eqs (14)-(17): where the base circle meets the plane.
    nx, ny, nz = (
        c * frame[2, 0] - s * frame[1, 0],
        c * frame[2, 1] - s * frame[1, 1],
        c * frame[2, 2] - s * frame[1, 2],
    )
    chord_ok = _crossings(apex, R, d_vo, r_vo, nx, ny, nz, sec.chord_cs)
    for j in range(2):
        if chord_ok:
            ct, st = r_vo * sec.chord_cs[j, 0], r_vo * sec.chord_cs[j, 1]
            bx, by, bz = _framed(
                apex[0] + R[0, 0] * d_vo + R[0, 1] * ct + R[0, 2] * st,
                apex[1] + R[1, 0] * d_vo + R[1, 1] * ct + R[1, 2] * st,
                apex[2] + R[2, 0] * d_vo + R[2, 1] * ct + R[2, 2] * st,
                frame,
            )
            sec.chord[j, 0], sec.chord[j, 1] = bx, c * by + s * bz
        else:
            sec.chord[j, 0], sec.chord[j, 1] = np.nan, np.nan
            sec.chord_cs[j, 0], sec.chord_cs[j, 1] = np.nan, np.nan
    # Classification by the angle between the plane and the axis (|n·a| vs sin alpha).
    sa = cones.sin_alpha[i]
    na = abs(R[0, 0] * nx + R[1, 0] * ny + R[2, 0] * nz)
    kind = BLANK
    if any_valid or chord_ok:
        if na > sa + _ANGLE_TOL:
            kind = CIRCLE if na > 1 - _ANGLE_TOL else ELLIPSE
        elif abs(na - sa) <= _ANGLE_TOL:
            kind = PARABOLA
        else:
            kind = HYPERBOLA
    if on_apex:
        kind = POINT if na > sa + _ANGLE_TOL else (LINE if na >= sa - _ANGLE_TOL else TRIANGLE)
        if kind == TRIANGLE and not corr.triangle:  # the original reduces eq. (12) to A^phi
            kind = POINT
    # Eq. (13): the symmetry-line point H, where the axis line meets the plane.
    xC, yC, zC = (
        base[0, K + 1],
        c * base[1, K + 1] + s * base[2, K + 1],
        c * base[2, K + 1] - s * base[1, K + 1],
    )
    dzc = zC - zA
    if abs(dzc) <= 1e-12 * scale:  # the axis is parallel to the plane
        sec.symmetry[0], sec.symmetry[1] = xC, yC
    else:
        t_h = -zA / dzc
        if corr.symmetry_abs:
            t_h = abs(t_h)
        sec.symmetry[0], sec.symmetry[1] = (xC - xA) * t_h + xA, (yC - yA) * t_h + yA
    # Inside the protected zone: the VO is the closing half-space (v - apex)·rel > 0.
    xr, yr, zr = (
        base[0, K + 2],
        c * base[1, K + 2] + s * base[2, K + 2],
        c * base[2, K + 2] - s * base[1, K + 2],
    )
    sec.halfplane[0], sec.halfplane[1], sec.halfplane[2] = xr, yr, xA * xr + yA * yr + zA * zr
    return INSIDE_CODE if cones.inside[i] else kind


@inline
def _pseudo_angle(y: float, x: float) -> float:
    """A number in [-2, 2] that grows with atan2(y, x) (the same order, no trigonometry); NaN
    for NaN input."""
    frac = y / (abs(x) + abs(y)) if x != 0.0 or y != 0.0 else 0.0
    if x >= 0.0 or x != x:
        return frac
    return (2.0 - abs(frac)) if y >= 0.0 else -(2.0 - abs(frac))


@kernel
def pyramid_base_points(pyramids: VOPyramids, j: int, frame: np.ndarray, out: np.ndarray) -> None:
    """The eight corners of C_pz (bits far, left, top of k pick hi over lo) in the planes'
    (e_x, e_y0, e_z0) frame, into ``out`` (3, 9), one row per axis; column 8 is the horizontal
    direction h towards the obstacle."""
    F, lo, hi = pyramids.frame[j], pyramids.lo[j], pyramids.hi[j]
    for k in range(8):
        a0 = hi[0] if k & 1 else lo[0]
        a1 = hi[1] if (k >> 1) & 1 else lo[1]
        a2 = hi[2] if (k >> 2) & 1 else lo[2]
        out[0, k], out[1, k], out[2, k] = _framed(
            a0 * F[0, 0] + a1 * F[1, 0] + a2 * F[2, 0],
            a0 * F[0, 1] + a1 * F[1, 1] + a2 * F[2, 1],
            a0 * F[0, 2] + a1 * F[1, 2] + a2 * F[2, 2],
            frame,
        )
    out[0, 8], out[1, 8], out[2, 8] = _framed(F[0, 0], F[0, 1], F[0, 2], frame)


@inline
def pyramid_section(
    pyramids: VOPyramids, j: int, base: np.ndarray, c: float, s: float, sec: Section
) -> int:
    """Section 4.2 for pyramid j on the plane with cos/sin phi = c, s: writes ``sec`` (chord:
    the two extreme points where C_pz's edges cross the plane; apex: the origin) and returns the
    kind. ``base`` is ``pyramid_base_points`` of the pyramid. Every plane contains the
    pyramid's apex (eq. 19): a triangle, a line or a point."""
    for a in range(2):
        sec.apex[a], sec.symmetry[a] = 0.0, np.nan
        sec.chord[a, 0], sec.chord[a, 1], sec.chord_cs[a, 0], sec.chord_cs[a, 1] = (
            np.nan,
            np.nan,
            np.nan,
            np.nan,
        )
    sec.halfplane[0], sec.halfplane[1], sec.halfplane[2] = (
        base[0, 8],
        c * base[1, 8] + s * base[2, 8],
        0.0,
    )
    # C_pz ∩ plane is the convex hull of the points where its edges cross the plane; the
    # extreme ones seen from the apex (the velocity origin) bound the section.
    n_cross, at_apex, sx, sy, mx, my = 0, False, 0.0, 0.0, 0.0, 0.0
    for e in range(BOX_EDGES.shape[0]):  # first pass: the mean direction of the crossings
        ka, kb = BOX_EDGES[e, 0], BOX_EDGES[e, 1]
        za, zb = c * base[2, ka] - s * base[1, ka], c * base[2, kb] - s * base[1, kb]
        if za * zb <= 0 and za != zb:
            f = za / (za - zb)
            x = base[0, ka] + f * (base[0, kb] - base[0, ka])
            ya, yb = c * base[1, ka] + s * base[2, ka], c * base[1, kb] + s * base[2, kb]
            y = ya + f * (yb - ya)
            norm = np.sqrt(x * x + y * y)
            n_cross, sx, sy = n_cross + 1, sx + x, sy + y
            if norm > 0:
                mx, my = mx + x / norm, my + y / norm
            else:
                at_apex = True  # A on the surface of C_pz: no wedge to speak of
    if n_cross == 0:
        return INSIDE_CODE if pyramids.inside[j] else POINT
    sec.symmetry[0], sec.symmetry[1] = sx / n_cross, sy / n_cross
    a_lo, a_hi = np.inf, -np.inf
    for e in range(BOX_EDGES.shape[0]):  # second pass: the extreme angles about that direction
        ka, kb = BOX_EDGES[e, 0], BOX_EDGES[e, 1]
        za, zb = c * base[2, ka] - s * base[1, ka], c * base[2, kb] - s * base[1, kb]
        if za * zb <= 0 and za != zb:
            f = za / (za - zb)
            x = base[0, ka] + f * (base[0, kb] - base[0, ka])
            ya, yb = c * base[1, ka] + s * base[2, ka], c * base[1, kb] + s * base[2, kb]
            y = ya + f * (yb - ya)
            ang = _pseudo_angle(mx * y - my * x, mx * x + my * y)
            if ang < a_lo:
                a_lo, sec.chord[0, 0], sec.chord[0, 1] = ang, x, y
            if ang > a_hi:
                a_hi, sec.chord[1, 0], sec.chord[1, 1] = ang, x, y
    kind = TRIANGLE
    if at_apex or not a_hi - a_lo > 1e-9:
        kind = LINE
        for a in range(2):
            sec.chord[a, 0], sec.chord[a, 1] = np.nan, np.nan
    return INSIDE_CODE if pyramids.inside[j] else kind


class Sections(NamedTuple):
    """Sections of n VO shapes on P planes, arrays (n, P, ...); NaN marks 'none'."""

    kind: np.ndarray  # (n, P) codes into KIND_NAMES
    curve: np.ndarray  # (n, P, K, 2) see Section
    chord: np.ndarray  # (n, P, 2, 2)
    chord_cs: np.ndarray  # (n, P, 2, 2)
    apex: np.ndarray  # (n, P, 2)
    symmetry: np.ndarray  # (n, P, 2)
    halfplane: np.ndarray  # (n, P, 3)
    t: np.ndarray  # (K,) generator angles of the curve samples
    corrections: Corrections

    @property
    def kind_names(self) -> np.ndarray:
        return KIND_NAMES[self.kind]

    @property
    def chord_t(self) -> np.ndarray:
        """(n, P, 2) the generator angles t of eq. (4) at the chord points (NaN: none)."""
        return np.arctan2(self.chord_cs[..., 1], self.chord_cs[..., 0])

    @property
    def vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, P, K + 3, 2) candidate polygon vertices (curve points, chord, apex) and which of
        them the section uses: the curve points found, the chord points where the base circle
        closes the section (3.1.4) or bounds a triangle (3.1.3), the apex of a triangle."""
        pts = np.concatenate([self.curve, self.chord, self.apex[:, :, None, :]], axis=2)
        use_chord = (
            np.isfinite(self.chord[..., 0])
            & (
                (self.kind != POINT)
                & (self.corrections.base_chord | (self.kind == LINE) | (self.kind == TRIANGLE))
            )[..., None]
        )
        mask = np.concatenate(
            [np.isfinite(self.curve[..., 0]), use_chord, (self.kind == TRIANGLE)[..., None]], axis=2
        )
        return pts, mask

    @property
    def polygon(self) -> np.ndarray:
        """(n, P, V, 2) the section's polygon, vertices in angular order, padded with NaN (all
        NaN when degenerate). Computed on each access."""
        poly = _angular_order(*self.vertices)
        return np.where((_polygon_area(poly) > 1e-14)[..., None, None], poly, np.nan)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Whether in-plane points lie inside each section: xy (P, M, 2) -> (n, P, M)."""
        xy = np.asarray(xy, dtype=float)
        poly = self.polygon
        inside = _in_polygon(poly, xy)
        if self.corrections.vo_lines:
            inside |= _beyond_chord(poly, self.apex, self.chord, xy)
        # The VO is open at its apex: zero relative velocity never collides (e.g. hovering
        # beside a static obstacle), although the apex is a vertex of the triangle.
        at_apex = np.linalg.norm(xy[None] - self.apex[:, :, None, :], axis=-1) <= 1e-9
        inside &= ~(at_apex & (self.kind == TRIANGLE)[..., None])
        hp = self.halfplane
        in_half = (
            hp[..., None, 0] * xy[None, ..., 0] + hp[..., None, 1] * xy[None, ..., 1]
            > hp[..., None, 2]
        )
        return np.where((self.kind == INSIDE_CODE)[..., None], in_half, inside)


def _empty_sections(n: int, P: int, K: int, t: np.ndarray, corr: Corrections) -> Sections:
    return Sections(
        kind=np.zeros((n, P), dtype=np.int64),
        curve=np.full((n, P, K, 2), np.nan),
        chord=np.full((n, P, 2, 2), np.nan),
        chord_cs=np.full((n, P, 2, 2), np.nan),
        apex=np.zeros((n, P, 2)),
        symmetry=np.full((n, P, 2), np.nan),
        halfplane=np.zeros((n, P, 3)),
        t=t,
        corrections=corr,
    )


@jit
def _section_at(out: Sections, i: int, p: int, curve: np.ndarray) -> Section:
    """Section i on plane p of ``out`` (views), with ``curve`` (2, K) as its curve: the caller
    copies it into out.curve[i, p] (K, 2) afterwards."""
    return Section(
        curve,
        out.chord[i, p],
        out.chord_cs[i, p],
        out.apex[i, p],
        out.symmetry[i, p],
        out.halfplane[i, p],
    )


@entry
def _fill_cone_sections(cones: VOCones, planes: AvoidancePlanes, out: Sections) -> None:
    cos_t, sin_t = np.cos(out.t), np.sin(out.t)
    K = out.t.shape[0]
    base, curve = np.empty((3, K + 3)), np.empty((2, K))
    for i in range(cones.d_oi.shape[0]):
        cone_base_points(cones, i, planes.frame, cos_t, sin_t, base)
        for p in range(planes.phi.shape[0]):
            out.kind[i, p] = cone_section(
                cones,
                i,
                base,
                planes.frame,
                np.cos(planes.phi[p]),
                np.sin(planes.phi[p]),
                out.corrections,
                _section_at(out, i, p, curve),
            )
            for k in range(K):
                out.curve[i, p, k, 0], out.curve[i, p, k, 1] = curve[0, k], curve[1, k]


@entry
def _fill_pyramid_sections(pyramids: VOPyramids, planes: AvoidancePlanes, out: Sections) -> None:
    base, curve = np.empty((3, 9)), np.empty((2, 0))
    for j in range(pyramids.L_pz.shape[0]):
        pyramid_base_points(pyramids, j, planes.frame, base)
        for p in range(planes.phi.shape[0]):
            out.kind[j, p] = pyramid_section(
                pyramids,
                j,
                base,
                np.cos(planes.phi[p]),
                np.sin(planes.phi[p]),
                _section_at(out, j, p, curve),
            )


def cone_sections(
    cones: VOCones,
    planes: AvoidancePlanes,
    *,
    corrections: Iterable[str] | None = None,
    n_samples: int = N_SAMPLES,
) -> Sections:
    """The conic sections of ``cones`` on ``planes`` (section 3.1), classified into KINDS."""
    corr = Corrections.of(corrections)
    t = generator_angles(n_samples)
    out = _empty_sections(cones.n, len(planes.phi), len(t), t, corr)
    _fill_cone_sections(cones, planes, out)
    return out


def pyramid_sections(pyramids: VOPyramids, planes: AvoidancePlanes) -> Sections:
    """Sections of VO pyramids (section 4.2). Every avoidance plane contains the apex (the
    velocity origin, eq. 19), so a section is a triangle (apex and the two extreme points where
    C_pz's edges meet the plane; with the VO lines, the whole wedge), a line, or the apex point.
    Inside C_pz the VO is every velocity with a horizontal component towards its centre."""
    out = _empty_sections(pyramids.n, len(planes.phi), 0, np.zeros(0), Corrections())
    _fill_pyramid_sections(pyramids, planes, out)
    return out


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


def _beyond_chord(
    poly: np.ndarray, apex: np.ndarray, chord: np.ndarray, xy: np.ndarray
) -> np.ndarray:
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
