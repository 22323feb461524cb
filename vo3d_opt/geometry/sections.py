"""Conic sections of VO cones and VO pyramids on the avoidance planes (sections 3.1 and 4.2).

Every section is described the paper's way, in plane coordinates (x^phi, y^phi): the curve of
eq. (12) (generators of the cone meeting the plane), the two points of eq. (17) where the base
circle B_vo meets it (the "chord"), the projected apex A^phi, the symmetry-line point H of
eq. (13), and the VOlineL / VOlineR rays of section 3.1.5. ``cone_section`` and
``pyramid_section`` compute one shape on one plane (compiled: ``vo3d_opt/algorithm/sections.hpp``;
the decision calls them directly); ``cone_sections`` / ``pyramid_sections`` fill all shapes on
all planes, and
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

import vo3d_opt._core as _core

from .cone import VOCones
from .frames import AvoidancePlanes
from .pyramid import VOPyramids

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

    def contains(self, xy: np.ndarray, polygon: np.ndarray | None = None) -> np.ndarray:
        """Whether in-plane points lie inside each section: xy (P, M, 2) -> (n, P, M).
        ``polygon``: :attr:`polygon`, when the caller tests several blocks of points."""
        xy = np.asarray(xy, dtype=float)
        poly = self.polygon if polygon is None else polygon
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
    return Sections(*_core.cone_sections(cones, planes, t, tuple(corr)), t, corr)


def pyramid_sections(pyramids: VOPyramids, planes: AvoidancePlanes) -> Sections:
    """Sections of VO pyramids (section 4.2). Every avoidance plane contains the apex (the
    velocity origin, eq. 19), so a section is a triangle (apex and the two extreme points where
    C_pz's edges meet the plane; with the VO lines, the whole wedge), a line, or the apex point.
    Inside C_pz the section is the half-plane of the velocities with a horizontal component
    towards its centre; under its top the VO holds every descent as well (``in_vo_pyramids``),
    which the QPs hold by a row of their own (``qp_limit_rows`` in algorithm/limits.hpp)."""
    return Sections(*_core.pyramid_sections(pyramids, planes), np.zeros(0), Corrections())


def _in_polygon(poly: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Even-odd crossing test of points (P, M, 2) in polygons (n, P, V, 2) padded with NaN.
    One section at a time: the (P, V, M) temporaries of one stay in the cache, where those of
    all at once took 1.7 times the time (the sampled formulation spends most of its time here)."""
    if len(poly) <= 1:
        return _crossings_odd(poly, xy)
    return np.concatenate([_crossings_odd(poly[i : i + 1], xy) for i in range(len(poly))])


def _crossings_odd(poly: np.ndarray, xy: np.ndarray) -> np.ndarray:
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
