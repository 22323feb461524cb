"""Tests of the paper's geometry (vo3d_opt.geometry): frames, VO cones, VO pyramids, the conic
sections on the avoidance planes with the six corrections of section 3.1, and exact membership.

Plane coordinates: every helper below describes an encounter in the coordinates of one avoidance
plane, (x, y, z) = (e1, e2(phi), n(phi)), so that a case reads the same whatever the preferred
direction and the plane angle; ``_world`` maps it to the world frame.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vo3d_opt import AgentState, Limits, VelocitySelector
from vo3d_opt.formulations.common import Options, prepare
from vo3d_opt.geometry import (
    CORRECTIONS,
    KINDS,
    VOCones,
    avoidance_frame,
    avoidance_planes,
    clearances,
    cone_penetration,
    cone_sections,
    default_phis,
    in_vo_cones,
    in_vo_pyramids,
    pyramid_entry_time,
    pyramid_sections,
    vo_cones,
    vo_pyramids,
)
from vo3d_opt.geometry.cone import outward_normals
from vo3d_opt.types import Box, Cylinder

REACH = 6.0  # largest own speed of interest (m/s) in these tests
N_SAMPLES = 72  # the sections' default number of generator samples

# Preferred directions and plane angles the constructed cases are checked on.
FRAMES = [
    ((1.0, 0.0, 0.0), 0.0),
    ((1.0, 2.0, 0.5), 0.7),
    ((-0.3, 0.4, -0.8), -1.2),
    ((0.0, 0.0, 1.0), np.pi / 2),  # vertical preferred velocity, vertical plane
]


# ----------------------------------------------------------------------------- helpers


def rotation_el_az(theta_el, psi_az):
    """R_{theta_el|psi_az} of eq. (6) as the paper writes it (the reference the compiled frames
    are checked against), shape (..., 3, 3)."""
    ct, st, cp, sp = np.cos(theta_el), np.sin(theta_el), np.cos(psi_az), np.sin(psi_az)
    zero = np.zeros_like(ct)
    return np.stack([np.stack([cp * ct, -sp, -cp * st], -1), np.stack([sp * ct, cp, -sp * st], -1),
                     np.stack([st, zero, ct], -1)], -2)


def rotation_plane(phi):
    """R_{P_phi} of eq. (8), shape (..., 3, 3)."""
    c, s = np.cos(phi), np.sin(phi)
    one, zero = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([one, zero, zero], -1), np.stack([zero, c, s], -1), np.stack([zero, -s, c], -1)], -2)


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _planes(pref, phi):
    return avoidance_planes(np.asarray(pref, dtype=float), np.atleast_1d(np.asarray(phi, dtype=float)))


def _world(planes, coords):
    """Plane coordinates (x along e1, y along e2, z along the normal) of the first plane -> world."""
    return np.asarray(coords, dtype=float) @ planes.to_plane[0]


def _case(pref, phi, rel, v_b, r_pz=10.0, p_a=(3.0, -7.0, 20.0), **cone_kw):
    """Cone and plane of an encounter given in plane coordinates (rel = p_B - p_A, v_b = V_B)."""
    planes = _planes(pref, phi)
    p_a = np.asarray(p_a, dtype=float)
    p_b = p_a + _world(planes, rel)
    cone_kw.setdefault("reach", REACH)
    cones = vo_cones(p_a, p_b[None], _world(planes, v_b)[None], r_pz, **cone_kw)
    return cones, planes


def _exact_on_plane(cones, planes, xy, **kw):
    """Exact membership of in-plane velocities xy (P, M, 2) lifted to 3D: (n, P, M)."""
    v = planes.lift(xy).reshape(-1, 3)
    return in_vo_cones(cones, v, **kw).reshape((cones.n,) + xy.shape[:2])


def _disc_grid(radius=REACH, m=61):
    g = np.linspace(-radius, radius, m)
    x, y = np.meshgrid(g, g)
    xy = np.stack([x.ravel(), y.ravel()], axis=-1)
    return xy[np.linalg.norm(xy, axis=1) <= radius]


def _polygon(sec, i=0, p=0):
    poly = sec.polygon[i, p]
    return poly[np.isfinite(poly[:, 0])]


def _inscribed_band(cones, n_samples=N_SAMPLES):
    """Largest penetration (m) a velocity can have while lying outside the K-gon pyramid
    inscribed in the cone through K generators (K = n_samples).

    A section polygon joins consecutive curve points of eq. (12); each such edge lies in the flat
    face (apex, B_vo(t_k), B_vo(t_k+1)), so the polygon is the section of the inscribed pyramid
    (plus the chord points, which are on the true cone). The faces of that pyramid are at angle
    theta from the axis with tan(theta) = tan(alpha) cos(pi / K), so a velocity that is in the
    cone but outside the polygon has an angle in (theta, alpha] to the axis and a penetration
    r_pz - d_oi sin(angle) below r_pz - d_oi sin(theta). For K = 72 that is at most about
    1e-3 r_pz (r_pz (1 - cos(pi/72)) for thin cones)."""
    sa = cones.sin_alpha
    with np.errstate(divide="ignore"):  # sin(alpha) = 1 inside the zone: no band needed there
        ta = sa / np.sqrt(1.0 - sa**2)
    theta = np.arctan(ta * np.cos(np.pi / n_samples))
    return cones.r_pz - cones.d_oi * np.sin(theta)


# ----------------------------------------------------------------------------- frames (eqs 6, 8)


def test_rotation_el_az_is_a_rotation_whose_first_column_points_at_b():
    rng = np.random.default_rng(0)
    rel = rng.normal(size=(50, 3)) * 20
    c = vo_cones(np.zeros(3), rel, np.zeros((50, 3)), 1.0)
    R = c.R
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(c.axis, _unit(rel), atol=1e-12)  # eq. (1) angles + eq. (6)
    assert np.allclose(R[:, 2, 1], 0.0)  # second body axis is horizontal (eq. 6)
    # eq. (6) with theta_el = psi_az = 0 is the identity
    assert np.allclose(rotation_el_az(np.array(0.0), np.array(0.0)), np.eye(3))


@pytest.mark.parametrize("pref,phi", FRAMES)
def test_avoidance_planes_frame(pref, phi):
    phis = default_phis(15)
    planes = _planes(pref, phis)
    frame = avoidance_frame(np.asarray(pref, dtype=float))
    assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(frame), 1.0)
    assert np.allclose(frame[0], _unit(pref))  # the common axis is the preferred direction
    assert abs(frame[1, 2]) < 1e-12  # e_y0 horizontal
    assert frame[2, 2] >= -1e-12  # e_z0 points up (or is horizontal for a vertical e1)
    # eq. (8): to_plane = R_{P_phi} @ frame; rows e1, e2(phi), n(phi) orthonormal
    assert np.allclose(planes.to_plane, rotation_plane(phis) @ frame)
    for T in planes.to_plane:
        assert np.allclose(T @ T.T, np.eye(3), atol=1e-12)
    # P_0 is the most horizontal plane: its e2 is horizontal
    i0 = int(np.argmin(np.abs(phis)))
    assert abs(planes.e2[i0, 2]) < 1e-12
    # lift and project are inverse on the plane; the preferred velocity is in every plane
    rng = np.random.default_rng(1)
    xy = rng.normal(size=(len(phis), 5, 2))
    back = np.einsum("pij,pmj->pmi", planes.to_plane, planes.lift(xy))
    assert np.allclose(back[..., :2], xy) and np.allclose(back[..., 2], 0.0, atol=1e-12)
    assert np.allclose(planes.project(np.asarray(pref, dtype=float))[:, 2], 0.0, atol=1e-12)


def test_default_phis():
    phis = default_phis(15)
    assert len(phis) == 13
    assert np.isclose(phis[0], -np.pi / 2) and np.isclose(phis[-1], np.pi / 2)
    assert len(default_phis(10)) == 19
    for bad in (0.0, -5.0, 200.0):
        with pytest.raises(ValueError):
            default_phis(bad)


# ----------------------------------------------------------------------------- VO cone (eqs 1–5)


def test_cone_quantities_eq_2_to_5():
    rng = np.random.default_rng(2)
    n = 40
    r = rng.uniform(1, 10, n)
    d = r * rng.uniform(1.05, 6, n)
    rel = _unit(rng.normal(size=(n, 3))) * d[:, None]
    v_b = rng.normal(size=(n, 3))
    p_a = rng.normal(size=3) * 10
    c = vo_cones(p_a, p_a + rel, v_b, r, virtual_sphere=False)
    assert np.all(c.tau == 1.0)
    assert np.allclose(c.d_oi, d)
    assert np.allclose(c.d_vo, (d**2 - r**2) / d)  # eq. (2)
    assert np.allclose(c.r_vo, r * np.sqrt(d**2 - r**2) / d)  # eq. (2)
    assert np.allclose(c.apex, v_b)  # eq. (3)
    assert np.allclose(c.center, v_b + c.d_vo[:, None] * _unit(rel))  # eq. (5)
    t = np.linspace(0, 2 * np.pi, 9)
    B = c.base_points(t)  # eq. (4)
    # the base circle is the tangency circle of the cone on the sphere |x - (V_B + rel)| = r_pz
    assert np.allclose(np.linalg.norm(B - (v_b + rel)[:, None], axis=-1), r[:, None])
    assert np.allclose(np.linalg.norm(B - v_b[:, None], axis=-1), np.sqrt(d**2 - r**2)[:, None])
    assert np.allclose(np.linalg.norm(B - c.center[:, None], axis=-1), c.r_vo[:, None])
    # generators are tangent to the sphere: (B - apex) ⟂ (B - sphere centre)
    dots = np.einsum("nki,nki->nk", B - v_b[:, None], B - (v_b + rel)[:, None])
    assert np.allclose(dots, 0.0, atol=1e-9)
    # outward normals: supporting planes along each generator
    nrm = outward_normals(c, t)
    assert np.allclose(np.linalg.norm(nrm, axis=-1), 1.0)
    assert np.allclose(np.einsum("nki,nki->nk", nrm, B - v_b[:, None]), 0.0, atol=1e-9)
    assert np.allclose(np.einsum("nki,ni->nk", nrm, c.axis), -c.sin_alpha[:, None])
    inner = c.center - c.apex  # the axis point is inside: strictly negative side
    assert np.all(np.einsum("nki,ni->nk", nrm, inner) < 0)


def test_virtual_sphere_rule():
    """Section 3.1.6 / eq. (18): tau >= 1.5 and large enough that the base lies beyond reach."""
    rng = np.random.default_rng(3)
    n = 300
    r = rng.uniform(1, 10, n)
    d = r * rng.uniform(1.01, 8, n)
    rel = _unit(rng.normal(size=(n, 3))) * d[:, None]
    v_b = _unit(rng.normal(size=(n, 3))) * rng.uniform(0, 4, (n, 1))
    plain = vo_cones(np.zeros(3), rel, v_b, r, virtual_sphere=False)
    c = vo_cones(np.zeros(3), rel, v_b, r, reach=REACH)
    assert np.all((c.tau == 1.0) | (c.tau >= 1.5))
    assert np.allclose(c.d_vo, plain.d_vo * c.tau) and np.allclose(c.r_vo, plain.r_vo * c.tau)
    # same half-angle: the virtual sphere tau r_pz at tau d_oi (eq. 18) spans the same cone
    assert np.allclose(c.r_vo / c.d_vo, plain.r_vo / plain.d_vo)
    # every velocity |v| <= reach lies axially before the base
    assert np.all(c.d_vo > REACH + np.linalg.norm(v_b, axis=1))
    expanded = c.tau > 1
    assert np.any(expanded) and np.any(~expanded)
    assert np.all(plain.d_vo[~expanded] >= REACH + np.linalg.norm(v_b[~expanded], axis=1))
    # without reach: the paper's rule, tau = 1.5 within 2 r_pz
    paper = vo_cones(np.zeros(3), rel, v_b, r)
    assert np.array_equal(paper.tau, np.where(d < 2 * r, 1.5, 1.0))
    # inside the protected zone no expansion
    inside = vo_cones(np.zeros(3), [[1.0, 0, 0]], [[0, 0, 0]], 5.0, reach=REACH)
    assert inside.inside[0] and inside.tau[0] == 1.0


# ----------------------------------------------------------------------------- 1. the eight kinds

S = 1.0 / 3.0  # sin(alpha) for d_oi = 30, r_pz = 10
C = np.sqrt(1 - S**2)
KIND_CASES = {
    # kind: (rel = p_B - p_A, V_B), plane coordinates (x = e1, y = e2, z = plane normal)
    # apex above the plane, cone opening upwards: the plane meets only the back nappe
    "blank": ((0.0, 0.0, 30.0), (0.5, -0.3, 1.0)),
    # apex on the plane, |n·a| = 1 > sin(alpha): only the apex
    "point": ((0.0, 0.0, 30.0), (1.0, 0.5, 0.0)),
    # apex on the plane, |n·a| == sin(alpha): tangent along one generator
    "line": ((30 * C, 0.0, 30 * S), (1.0, 2.0, 0.0)),
    # apex on the plane, |n·a| < sin(alpha): the 2D situation of section 3.1.3
    "triangle": ((25.0, 5.0, 4.0), (0.0, 1.0, 0.0)),
    # axis along the plane normal (perpendicular to e1), apex below the plane
    "circle": ((0.0, 0.0, 30.0), (0.5, 1.0, -1.0)),
    # sin(alpha) < |n·a| < 1
    "ellipse": ((15.0, 0.0, 26.0), (0.0, 0.0, -1.0)),
    # |n·a| == sin(alpha) exactly: the axis makes the angle alpha with the plane
    "parabola": ((30 * C, 0.0, 30 * S), (0.5, 0.0, -1.0)),
    # |n·a| < sin(alpha), apex off the plane
    "hyperbola": ((30.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
    # A within r_pz of B
    "inside": ((5.0, 2.0, 1.0), (0.0, 0.0, -1.0)),
}


@pytest.mark.parametrize("pref,phi", FRAMES)
@pytest.mark.parametrize("kind", list(KIND_CASES))
def test_constructed_section_kinds(kind, pref, phi):
    rel, v_b = KIND_CASES[kind]
    cones, planes = _case(pref, phi, rel, v_b)
    sec = cone_sections(cones, planes)
    assert sec.kind_names[0, 0] == kind
    na = abs(cones.axis[0] @ planes.normal[0])
    sa = cones.sin_alpha[0]
    apex_z = cones.apex[0] @ planes.normal[0]
    poly = _polygon(sec)
    xy = _disc_grid()[None]
    got = sec.contains(xy)[0, 0]
    exact = _exact_on_plane(cones, planes, xy)[0, 0]
    if kind == "blank":
        assert len(poly) == 0 and not got.any() and not exact.any()
    elif kind == "point":
        assert abs(apex_z) < 1e-9 and na > sa
        assert len(poly) == 0 and not got.any()
        assert np.allclose(sec.apex[0, 0], np.asarray(v_b)[:2])  # A^phi of eq. (7)
    elif kind == "line":
        assert abs(apex_z) < 1e-9 and abs(na - sa) < 1e-9
        assert len(poly) == 0  # a degenerate (zero-area) section
        # eq. (17) has a double root (the tangent generator's base point), or, rounded, none
        ch = sec.chord[0, 0]
        assert np.isnan(ch).all() or np.allclose(ch[0], ch[1], atol=1e-6)
    elif kind == "triangle":
        assert abs(apex_z) < 1e-9 and na < sa
        assert len(poly) == 3
        assert np.any(np.all(np.isclose(poly, sec.apex[0, 0]), axis=1))  # the apex is a vertex
        assert np.isfinite(sec.chord[0, 0]).all()
    elif kind == "circle":
        assert np.isclose(na, 1.0)
        rad = np.linalg.norm(poly - sec.symmetry[0, 0], axis=1)  # H is the centre
        assert len(poly) == N_SAMPLES and np.allclose(rad, rad[0])
        assert not np.isfinite(sec.chord[0, 0]).any()
    elif kind == "ellipse":
        assert sa < na < 1
        assert len(poly) == N_SAMPLES and not np.isfinite(sec.chord[0, 0]).any()
    elif kind == "parabola":
        assert abs(na - sa) < 1e-12
        assert np.isfinite(sec.chord[0, 0]).all()  # closed by the base points (3.1.4)
    elif kind == "hyperbola":
        assert na < sa and abs(apex_z) > 0.5
        assert np.isfinite(sec.chord[0, 0]).all()
    elif kind == "inside":
        assert cones.inside[0]
    if kind in ("circle", "ellipse", "parabola", "hyperbola", "triangle", "inside"):
        assert got.any() and exact.any()
    # the section agrees with the exact membership away from the boundary; the apex itself
    # (v = V_B, no relative motion: never in the VO) is a boundary point where
    # cone_penetration jumps, and the polygon test counts the triangle's apex vertex as inside
    pen = cone_penetration(cones, planes.lift(xy).reshape(-1, 3))[0]
    band = np.abs(pen) < 2 * _inscribed_band(cones)[0] + 1e-9
    band |= np.linalg.norm(xy[0] - sec.apex[0, 0], axis=1) < 1e-9
    assert np.all((got == exact) | band)


def test_kind_rule_on_random_planes():
    """The classification rule: |n·a| vs sin(alpha) and whether the apex lies on the plane."""
    rng = np.random.default_rng(4)
    for _ in range(30):
        r = rng.uniform(2, 10)
        rel = _unit(rng.normal(size=3)) * r * rng.uniform(1.1, 5)
        v_b = _unit(rng.normal(size=3)) * rng.uniform(0.5, 4)
        planes = _planes(_unit(rng.normal(size=3)), default_phis(15))
        c = vo_cones(np.zeros(3), rel[None], v_b[None], r, reach=REACH)
        sec = cone_sections(c, planes)
        na = np.abs(planes.normal @ c.axis[0])
        names = sec.kind_names[0]
        sa = c.sin_alpha[0]
        cut = names != "blank"
        assert np.all(na[names == "hyperbola"] < sa)
        assert np.all(na[np.isin(names, ["ellipse", "circle"])] > sa)
        # with |n·a| > sin(alpha) every generator moves the same way along the normal, so the
        # forward nappe meets the plane only when the axis points from the apex towards it
        z_a = planes.normal @ c.apex[0]
        towards = z_a * (planes.normal @ c.axis[0]) < 0
        assert not np.any(cut[(na > sa) & ~towards])


@pytest.mark.parametrize("altitude,expected", [(10.0, "triangle"), (50.0, "point")])
def test_pyramid_kinds(altitude, expected):
    ob = Cylinder(center=(30.0, 4.0), radius=3.0, height=20.0)  # h_pz = 22
    p_a = np.array([0.0, 0.0, altitude])
    pyr = vo_pyramids(p_a, [ob])
    planes = _planes((1.0, 0.0, 0.0), 0.0)  # the horizontal plane through A
    sec = pyramid_sections(pyr, planes)
    assert sec.kind_names[0, 0] == expected
    xy = _disc_grid()[None]
    got = sec.contains(xy)[0, 0]
    exact = in_vo_pyramids(pyr, planes.lift(xy)[0])[0]
    # v = 0 (hovering: never enters C_pz) is the pyramid's apex; the polygon test counts the
    # triangle's apex vertex as inside, so the comparison leaves it out
    away = np.linalg.norm(xy[0], axis=1) > 1e-9
    assert np.array_equal(got[away], exact[away])
    assert got.any() == (expected == "triangle")
    if expected == "triangle":
        assert len(_polygon(sec)) == 3
        assert np.allclose(sec.apex[0, 0], 0.0)  # eq. (19): the apex is the velocity origin


def _depths(pyr, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Brute force: how far points q (M, 3), relative to p_A, lie inside pyramid 0's prism
    from its side (the nearest of its four walls) and from its top."""
    x = q @ pyr.frame[0].T
    side = np.minimum(x[:, :2] - pyr.lo[0, :2], pyr.hi[0, :2] - x[:, :2]).min(axis=1)
    return side, pyr.hi[0, 2] - x[:, 2]


@pytest.mark.parametrize(("z", "top"), [(5.0, False), (14.2, True)])
def test_pyramid_inside_kind(z, top):
    """Inside C_pz the VO is the velocities with a horizontal component towards its centre and,
    just under its top, the descents too; the section is the half-plane of the first, so on
    every plane it lies in the VO, and is all of it when low down."""
    ob = Box(center=(1.0, 1.0), size=(4.0, 2.0), height=15.0)
    p_a = np.array([0.0, 0.0, z])
    pyr = vo_pyramids(p_a, [ob])
    assert pyr.inside[0]
    planes = _planes((0.3, -1.0, 0.2), default_phis(15))
    sec = pyramid_sections(pyr, planes)
    assert np.all(sec.kind_names == "inside")
    xy = np.random.default_rng(5).uniform(-REACH, REACH, (len(planes.phi), 200, 2))
    got = sec.contains(xy)[0]
    v = planes.lift(xy)
    exact = in_vo_pyramids(pyr, v.reshape(-1, 3))[0].reshape(got.shape)
    toward = v @ np.r_[_unit([1.0, 1.0]), 0.0] > 0
    assert np.array_equal(got, toward)
    assert np.array_equal(exact, toward | (v[..., 2] < 0) if top else toward)
    assert (exact & ~got).any() == top


@pytest.mark.parametrize("raised", [False, True])
def test_inside_a_prism_the_vo_is_closing_in_by_brute_force(raised):
    """Inside C_pz, anywhere in it (near the side, the top, or the edge between them): a
    velocity is in the VO, closes on the zone (``closing_rate``) and intrudes at once
    (``time_to_intrusion`` 0) exactly when a short step along it takes A deeper from the side
    or, under the top (the top the nearer face, or A over the roof), from the top; the closing
    rate is the sum of both ways in, the clearance the slower of the two ways out. ``raised``:
    a prism whose top margin (4 m) exceeds its side margin (2 m), so that the roof's edge has
    points where the side is nearer."""
    rng = np.random.default_rng(11)
    ob = Cylinder(center=(0.0, 0.0), radius=3.0, height=20.0,
                  **(dict(L_pz=10.0, h_pz=24.0) if raised else {}))

    def encounter(p_a: np.ndarray):  # the decision's planning prism, with its buffer
        return prepare(AgentState(position=p_a, velocity=np.zeros(3)), np.zeros(3), [], [ob],
                       Limits(speed=(0.0, 8.0), altitude=(0.0, 60.0)), 0.1, Options())

    pyr0 = encounter(np.zeros(3)).vos.pyramids
    half, top = pyr0.L_pz[0] / 2, pyr0.h_pz[0]
    faces = {True: 0, False: 0}  # top nearer, side nearer
    roof_edge = 0  # over the roof, the side nearer
    for _ in range(300):
        r, a = half * rng.uniform(0.0, 0.98), rng.uniform(0, 2 * np.pi)
        p_a = np.array([r * np.cos(a), r * np.sin(a), top - rng.uniform(0.01, 1.2 * half)])
        gap = (half - r) - (top - p_a[2])  # > 0: the top is the nearer face
        if abs(gap) < 1e-3 or r < 1e-3:  # on an edge the nearest face is either one
            continue
        enc = encounter(p_a)
        pyr = enc.vos.pyramids
        assert pyr.inside[0]
        faces[bool(gap > 0)] += 1
        over_roof = r < ob.radius and p_a[2] >= ob.height
        roof_edge += over_roof and gap < 0
        assert pyr.over_roof[0] == over_roof
        v = rng.uniform(-4.0, 4.0, (40, 3))
        # a step short enough that the nearest wall (the near one, by r nearer than the
        # others) and the top stay the nearest of their kinds
        eps = 0.1 * min(half - r, top - p_a[2], r) / 4.0 / np.sqrt(3)
        side0, top0 = _depths(pyr, np.zeros((1, 3)))
        side1, top1 = _depths(pyr, eps * v)
        from_side = (side1 - side0) / eps
        from_top = (top1 - top0) / eps if gap > 0 or over_roof else np.full(len(v), -np.inf)
        rate = np.maximum(from_side, from_top)
        keep = np.abs(rate) > 1e-6  # not along a face
        closing = rate[keep] > 0
        assert np.array_equal(in_vo_pyramids(pyr, v)[0][keep], closing)
        deeper = np.maximum(from_side, 0.0) + np.maximum(from_top, 0.0)  # both ways summed
        np.testing.assert_allclose(enc.closing_rate(v), deeper, atol=1e-9)
        assert np.array_equal(enc.time_to_intrusion(v)[keep] == 0.0, closing)
        np.testing.assert_allclose(clearances(VOCones.empty(), pyr, v), -rate, atol=1e-9)
    assert min(faces.values()) > 50
    assert roof_edge > 10 if raised else roof_edge == 0


@pytest.mark.parametrize("formulation", ["plane_qp", "cone_qp", "sampled"])
def test_beside_a_box_under_its_prisms_top_no_answer_closes_in(formulation):
    """A vehicle 0.5 m from a box's long wall and 0.5 m under its top is nearer the top of the
    turned square C_pz than its side, though beside the box below the box's own top: its
    answer, asked to fly into the wall, neither goes towards the centre nor sinks."""
    ob = Box(center=(0.0, 0.0), size=(8.0, 2.0), height=15.0)
    p = np.array([0.0, -1.5, 14.5])
    pyr = vo_pyramids(p, [ob])
    assert pyr.inside[0] and pyr.hi[0, 2] < -pyr.lo[0, 0]  # the top is the nearer face
    d = VelocitySelector(formulation).select(
        own=AgentState(position=p, velocity=np.zeros(3)), preferred_velocity=(0.0, 3.0, -0.5),
        neighbors=[], obstacles=[ob], limits=Limits(speed=(0, 4), altitude=(0, 60)), dt=0.1)
    assert d.status == "inside_protected_zone"
    assert d.velocity @ pyr.frame[0, 0] <= 0.0 and d.velocity[2] >= 0.0
    assert ob.surface_distance((p + 0.5 * d.velocity)[None])[0] >= ob.surface_distance(p[None])[0]


def test_unknown_correction_rejected():
    cones, planes = _case((1, 0, 0), 0.0, (30.0, 0, 0), (0, 0, -1.0))
    with pytest.raises(ValueError, match="corrections"):
        cone_sections(cones, planes, corrections={"tg_range", "typo"})


# ----------------------------------------------------------------------------- 2. agreement


def _random_cone_encounter(rng):
    r = rng.uniform(1.0, 12.0)
    d = r * rng.uniform(1.0 + 1e-3, 6.0)  # d_oi in (r_pz, 6 r_pz]
    p_a = rng.uniform(-50, 50, 3)
    rel = _unit(rng.normal(size=3)) * d
    v_b = _unit(rng.normal(size=3)) * 4.0 * rng.uniform(0, 1) ** (1 / 3)  # |V_B| <= 4
    # preferred direction: random, or towards B (more planes cut the cone)
    pref = rng.normal(size=3) if rng.uniform() < 0.5 else rel + rng.normal(size=3) * d * 0.3
    return p_a, p_a + rel, v_b, r, _unit(pref)


def _plane_samples(rng, n_planes, m, radius=REACH):
    rad = radius * np.sqrt(rng.uniform(0, 1, (n_planes, m)))
    ang = rng.uniform(0, 2 * np.pi, (n_planes, m))
    return np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=-1)


def test_cone_sections_agree_with_exact_membership():
    """>= 500 random encounters x 13 planes x 160 in-plane velocities with |v| <= reach.

    Band: a velocity is excluded when |cone_penetration| < 2 delta_K, delta_K being the largest
    penetration outside the inscribed 72-gon pyramid (``_inscribed_band``; <= ~1e-3 r_pz).
    With the virtual sphere chosen from ``reach`` the base is beyond every |v| <= reach, so the
    polygon of curve points is the only approximation left in that disc."""
    rng = np.random.default_rng(20240611)
    phis = default_phis(15)
    tally = _Agreement()
    for _ in range(520):
        p_a, p_b, v_b, r, pref = _random_cone_encounter(rng)
        cones = vo_cones(p_a, p_b[None], v_b[None], r, reach=REACH)
        planes = _planes(pref, phis)
        sec = cone_sections(cones, planes)
        xy = _plane_samples(rng, len(phis), 160)
        got = sec.contains(xy)[0]
        v = planes.lift(xy).reshape(-1, 3)
        exact = in_vo_cones(cones, v)[0].reshape(got.shape)
        pen = cone_penetration(cones, v)[0].reshape(got.shape)
        tally.add(sec, got, exact, band=np.abs(pen) < 2 * _inscribed_band(cones)[0] + 1e-9 * r)
    tally.check({"blank", "ellipse", "hyperbola"})


class _Agreement:
    """Counts of a sections-vs-exact-membership comparison, outside the band of samples too
    close to the boundary to call."""

    def __init__(self) -> None:
        self.total = self.banded = self.inside = self.wrong = 0
        self.kinds: set[str] = set()

    def add(self, sec, got, exact, band) -> None:
        self.total += got.size
        self.banded += band.sum()
        self.inside += (exact & ~band).sum()
        self.wrong += ((got != exact) & ~band).sum()
        self.kinds.update(sec.kind_names[0].tolist())

    def check(self, kinds: set[str]) -> None:
        assert self.wrong == 0
        assert self.banded < 0.1 * self.total
        assert self.inside > 0.02 * self.total  # the test has teeth: many velocities are in a VO
        assert kinds <= self.kinds


def _random_obstacle(rng):
    c = rng.uniform(-30, 30, 2)
    h = rng.uniform(2.0, 40.0)
    kw = {}
    if rng.uniform() < 0.3:  # explicit protected prism
        kw = dict(h_pz=h + rng.uniform(0, 5))
    if rng.uniform() < 0.5:
        radius = rng.uniform(0.5, 8)
        if rng.uniform() < 0.3:
            kw["L_pz"] = 2 * radius + rng.uniform(0, 4)
        return Cylinder(center=c, radius=radius, height=h, **kw)
    size = rng.uniform(0.5, 12, 2)
    if rng.uniform() < 0.3:
        kw["L_pz"] = float(np.hypot(*size)) + rng.uniform(0, 4)
    return Box(center=c, size=size, height=h, yaw=rng.uniform(-np.pi, np.pi), **kw)


def _random_outside_position(rng, ob):
    L, H = ob.side, ob.prism_height
    while True:
        z = rng.uniform(0.0, 60.0)  # includes altitudes above h_pz
        ang = rng.uniform(0, 2 * np.pi)
        dist = rng.uniform(0.0, 3 * L + 20)
        if dist >= L / 2 + 0.1 or z > H + 0.1:
            return np.array([ob.center[0] + dist * np.cos(ang), ob.center[1] + dist * np.sin(ang), z])


def _pyramid_boundary(pyr, planes, xy, eps=1e-6):
    """Samples whose exact membership changes when turned by +-eps rad in their plane."""
    base = in_vo_pyramids(pyr, planes.lift(xy).reshape(-1, 3)).reshape((pyr.n,) + xy.shape[:2])
    perp = np.stack([-xy[..., 1], xy[..., 0]], axis=-1)
    changed = np.zeros_like(base)
    for sign in (1.0, -1.0):
        v = planes.lift(xy + sign * eps * perp).reshape(-1, 3)
        changed |= in_vo_pyramids(pyr, v).reshape(base.shape) != base
    return base, changed


def test_pyramid_sections_agree_with_exact_membership():
    """>= 500 random cylinders/boxes (random yaw, sizes, heights, explicit or derived L_pz/h_pz),
    vehicles outside the prism at altitudes up to 60 m, 13 planes, 160 velocities each.
    Band: samples whose membership flips under a 1e-6 rad in-plane turn."""
    rng = np.random.default_rng(7)
    phis = default_phis(15)
    tally, above = _Agreement(), 0
    for _ in range(520):
        ob = _random_obstacle(rng)
        p_a = _random_outside_position(rng, ob)
        above += p_a[2] > ob.prism_height
        pyr = vo_pyramids(p_a, [ob])
        assert not pyr.inside[0]
        to_ob = np.r_[ob.center - p_a[:2], rng.normal() * 5]
        pref = rng.normal(size=3) if rng.uniform() < 0.5 else to_ob + rng.normal(size=3) * 5
        planes = _planes(_unit(pref), phis)
        sec = pyramid_sections(pyr, planes)
        xy = _plane_samples(rng, len(phis), 160)
        got = sec.contains(xy)[0]
        exact, band = _pyramid_boundary(pyr, planes, xy)
        tally.add(sec, got, exact[0], band[0])
    tally.check({"triangle", "point"})
    assert above > 50


# ----------------------------------------------------------------------------- 3. corrections


def _contains(cones, planes, xy, **kw):
    sec = cone_sections(cones, planes, **kw)
    return sec, sec.contains(np.asarray(xy, dtype=float).reshape(1, -1, 2))[0, 0]


def _without(name):
    return CORRECTIONS - {name}


def test_correction_tg_range_3_1_1():
    """Hyperbola of Fig. 3: without 0 <= t_g <= 1 the back nappe adds a spurious branch."""
    cones, planes = _case((1, 0, 0), 0.0, (30.0, 0.0, 0.0), (0.0, 0.0, -1.0))
    v = [(-2.0, 0.0)]  # flying straight away from B: safe
    exact = _exact_on_plane(cones, planes, np.array([v]))[0, 0]
    sec_ok, ok = _contains(cones, planes, v)
    sec_bad, bad = _contains(cones, planes, v, corrections=_without("tg_range"))
    assert not exact[0]
    assert not ok[0] and bad[0]  # the uncorrected variant marks a safe velocity unsafe
    # the error side: vertices behind the projected apex, against the projected axis
    d = (cones.center[0] - cones.apex[0]) @ planes.to_plane[0, :2].T
    side_ok = (_polygon(sec_ok) - sec_ok.apex[0, 0]) @ d
    side_bad = (_polygon(sec_bad) - sec_bad.apex[0, 0]) @ d
    assert np.all(side_ok > 0) and np.any(side_bad < 0)


def test_correction_tg_range_back_nappe_only():
    """Apex above the plane, cone opening upwards: only the back nappe meets the plane."""
    cones, planes = _case((1, 0, 0), 0.0, (0.0, 0.0, 30.0), (0.0, 0.0, 1.0))
    v = [(0.0, 0.0)]  # hovering: B climbs away, safe
    assert not _exact_on_plane(cones, planes, np.array([v]))[0, 0, 0]
    sec_ok, ok = _contains(cones, planes, v)
    sec_bad, bad = _contains(cones, planes, v, corrections=_without("tg_range"))
    assert sec_ok.kind_names[0, 0] == "blank" and not ok[0]
    assert sec_bad.kind_names[0, 0] != "blank" and bad[0]


def test_correction_symmetry_abs_3_1_2():
    """Axis pointing away from the plane (t_h < 0) while the plane still cuts the cone.

    Let A = A^phi (projected apex), d = (C_vo - A_vo) projected on the plane (the in-plane
    direction of the symmetry line). The real section lies on the side (q - A)·d > 0. The
    uncorrected H (t_h < 0) is where the backward extension of the symmetry line meets the
    plane: (H - A)·d < 0, the error side; the corrected H (|t_h|) has (H - A)·d > 0 at the
    same distance from A, on the same line."""
    cones, planes = _case((1, 0, 0), 0.0, (30.0, 0.0, -3.0), (0.0, 0.0, -1.0))
    T = planes.to_plane[0]
    z_a = T[2] @ cones.apex[0]
    z_c = T[2] @ cones.center[0]
    t_h = -z_a / (z_c - z_a)
    assert t_h < 0
    ok = cone_sections(cones, planes)
    bad = cone_sections(cones, planes, corrections=_without("symmetry_abs"))
    assert ok.kind_names[0, 0] == bad.kind_names[0, 0] == "hyperbola"
    a = ok.apex[0, 0]
    d = (cones.center[0] - cones.apex[0]) @ T[:2].T
    poly = _polygon(ok)
    assert len(poly) > 3 and np.all((poly - a) @ d > 0)  # the real section's side
    h_ok, h_bad = ok.symmetry[0, 0], bad.symmetry[0, 0]
    assert (h_ok - a) @ d > 0
    assert (h_bad - a) @ d < 0
    cross = lambda u, w: u[0] * w[1] - u[1] * w[0]  # noqa: E731
    assert abs(cross(h_ok - a, d)) < 1e-9 and abs(cross(h_bad - a, d)) < 1e-9
    assert np.isclose(np.linalg.norm(h_ok - a), np.linalg.norm(h_bad - a))
    # the uncorrected H is the true meeting point of the line A_vo + s (C_vo - A_vo), s < 0
    s = -z_a / (T[2] @ (cones.center[0] - cones.apex[0]))
    meet = cones.apex[0] + s * (cones.center[0] - cones.apex[0])
    assert s < 0 and np.allclose(T[:2] @ meet, h_bad)
    # sections are shared, only H changes
    assert np.array_equal(ok.polygon, bad.polygon, equal_nan=True)


def test_symmetry_point_defined_when_axis_parallel_to_plane():
    """Section 3.1.2: a plane cutting the cone but parallel to its symmetry line still gets H."""
    cones, planes = _case((1, 0, 0), 0.0, (30.0, 0.0, 0.0), (0.0, 0.0, -1.0))
    sec = cone_sections(cones, planes)
    assert sec.kind_names[0, 0] == "hyperbola"
    assert np.isfinite(sec.symmetry[0, 0]).all()


def test_correction_triangle_3_1_3():
    """Apex, p_A and p_B on one plane (2D situation): the original reduces eq. (12) to the
    single point A^phi and marks a colliding velocity safe."""
    cones, planes = _case((1, 0, 0), 0.0, (30.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    v = [(3.0, 1.0)]  # V_B + 3 m/s straight at B: collides
    assert _exact_on_plane(cones, planes, np.array([v]))[0, 0, 0]
    sec_ok, ok = _contains(cones, planes, v)
    sec_bad, bad = _contains(cones, planes, v, corrections=_without("triangle"))
    assert sec_ok.kind_names[0, 0] == "triangle" and ok[0]
    assert sec_bad.kind_names[0, 0] == "point" and not bad[0]


def test_correction_base_chord_3_1_4():
    """Incomplete hyperbola: with 30 generator samples the curve points of eq. (12) stop at
    x ~ 4.1 m/s, well short of the base (x = 26.7); without the base points of eq. (17) the
    velocity (5, 0) — straight at B, deep inside the cone — is marked safe."""
    cones, planes = _case((1, 0, 0), 0.0, (30.0, 0.0, 0.0), (0.0, 0.0, -0.3))
    v = [(5.0, 0.0)]
    xy = np.array([v])
    assert _exact_on_plane(cones, planes, xy)[0, 0, 0]
    pen = cone_penetration(cones, planes.lift(xy)[0])[0, 0]
    assert pen > 0.5 * cones.r_pz[0]  # far from the boundary band
    sec_ok, ok = _contains(cones, planes, v, n_samples=30)
    sec_bad, bad = _contains(cones, planes, v, corrections=_without("base_chord"), n_samples=30)
    assert ok[0] and not bad[0]
    assert sec_ok.kind_names[0, 0] == sec_bad.kind_names[0, 0] == "hyperbola"
    assert _polygon(sec_bad)[:, 0].max() < v[0][0] < sec_ok.chord[0, 0, :, 0].min()


def test_correction_vo_lines_3_1_5():
    """Close encounter, no virtual sphere (tau = 1): the base circle cuts the plane at x = 1.9,
    inside the speed range; the part of the protected zone removed by the cone lies beyond it.
    Without VOlineL/VOlineR the velocity (4, 0) straight at B is marked safe."""
    cones, planes = _case((1, 0, 0), 0.0, (11.0, 0.0, 0.0), (0.0, 0.0, -0.5), virtual_sphere=False)
    assert cones.tau[0] == 1.0
    v = [(4.0, 0.0)]
    assert _exact_on_plane(cones, planes, np.array([v]))[0, 0, 0]
    sec_ok, ok = _contains(cones, planes, v)
    sec_bad, bad = _contains(cones, planes, v, corrections=_without("vo_lines"))
    chord = sec_ok.chord[0, 0]
    assert np.all(np.linalg.norm(chord, axis=1) < REACH)  # the base cuts within reach
    assert v[0][0] > chord[:, 0].max()  # beyond the chord
    assert ok[0] and not bad[0]


def test_correction_virtual_sphere_3_1_6():
    """Close encounter with the axis rising towards the plane: with tau = 1 the base circle cuts
    the plane within reach *behind* the projected apex (d_vo + (a·n) z_A < 0), so the VO lines
    point the wrong way and the velocity on the symmetry line (3.6, 0) — straight through B's
    centre — is marked safe. The virtual sphere (tau from reach) pushes the base beyond reach."""
    args = ((1, 0, 0), 0.0, (9.0, 0.0, 5.0), (0.0, 0.0, -2.0))
    off, planes = _case(*args, virtual_sphere=False)
    on, _ = _case(*args, virtual_sphere=True)
    assert off.tau[0] == 1.0 and on.tau[0] >= 1.5
    v = [(3.6, 0.0)]
    xy = np.array([v])
    assert _exact_on_plane(on, planes, xy)[0, 0, 0]
    assert np.isclose(cone_penetration(on, planes.lift(xy)[0])[0, 0], on.r_pz[0])  # on the axis
    sec_off, got_off = _contains(off, planes, v)
    sec_on, got_on = _contains(on, planes, v)
    assert np.all(np.linalg.norm(sec_off.chord[0, 0], axis=1) < REACH)  # base cuts within reach
    assert np.all(np.linalg.norm(sec_on.chord[0, 0], axis=1) > REACH)
    assert not got_off[0] and got_on[0]


# ----------------------------------------------------------------------------- 4. exact membership


def _brute_force_cone(cones, v, t_max=100.0, n_t=4001):
    """Minimum distance over sampled times of A's relative motion to B's centre (n, M)."""
    t = np.linspace(0.0, t_max, n_t)
    u = v[None, :, :] - cones.apex[:, None, :]  # (n, M, 3)
    pos = cones.rel[:, None, None, :] - u[:, :, None, :] * t[None, None, :, None]
    return np.linalg.norm(pos, axis=-1).min(axis=-1), t[1] - t[0]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_in_vo_cones_matches_simulated_relative_motion(seed):
    rng = np.random.default_rng(seed)
    n = 3
    r = rng.uniform(1, 10, n)
    d = r * rng.uniform(1.05, 6, n)
    rel = _unit(rng.normal(size=(n, 3))) * d[:, None]
    v_b = _unit(rng.normal(size=(n, 3))) * rng.uniform(0, 4, (n, 1))
    cones = vo_cones(np.zeros(3), rel, v_b, r, reach=REACH)
    # random velocities, half of them aimed near B
    v = _unit(rng.normal(size=(40, 3))) * rng.uniform(0, REACH, (40, 1))
    k = rng.integers(0, n, 40)
    aim = v_b[k] + (rel[k] + rng.normal(size=(40, 3)) * r[k, None]) / rng.uniform(2, 40, (40, 1))
    v = np.concatenate([v, aim])
    got = in_vo_cones(cones, v, horizon=100.0)
    closest, dt = _brute_force_cone(cones, v)
    speed = np.linalg.norm(v[None] - cones.apex[:, None], axis=-1)
    clear = np.abs(closest - r[:, None]) > speed * dt + 1e-9
    assert np.array_equal(got[clear], (closest < r[:, None])[clear])
    # without a horizon, membership is the infinite cone: angle to the axis below alpha
    u = v[None] - cones.apex[:, None]
    cos_ang = np.einsum("nmi,ni->nm", u, cones.axis) / np.maximum(np.linalg.norm(u, axis=-1), 1e-300)
    in_cone = cos_ang > cones.cos_alpha[:, None]
    pen = cone_penetration(cones, v)
    far = np.abs(pen) > 1e-9
    assert np.array_equal(in_vo_cones(cones, v)[far], in_cone[far])
    assert np.array_equal(in_cone[far], (pen > 0)[far])


def test_cone_horizon_and_tolerance():
    cones = vo_cones(np.zeros(3), [[30.0, 0, 0]], [[0.0, 1.0, 0]], 10.0)
    v = np.array([[2.0, 1.0, 0.0]])  # relative closing speed 2: enters at t = (30 - 10) / 2 = 10 s
    assert in_vo_cones(cones, v)[0, 0]
    assert in_vo_cones(cones, v, horizon=10.5)[0, 0]
    assert not in_vo_cones(cones, v, horizon=9.5)[0, 0]
    assert not in_vo_cones(cones, np.array([[-2.0, 1.0, 0.0]]))[0, 0]  # moving away
    assert not in_vo_cones(cones, np.array([[0.0, 1.0, 0.0]]))[0, 0]  # same velocity as B
    # a grazing velocity: closest approach exactly 10 m, i.e. r_pz; tol widens or shrinks
    ang = np.arcsin(10.0 / 30.0)
    graze = np.array([[2 * np.cos(ang - 0.01), 1 + 2 * np.sin(ang - 0.01), 0.0]])
    assert in_vo_cones(cones, graze)[0, 0]
    assert not in_vo_cones(cones, graze, tol=-0.5)[0, 0]
    miss = np.array([[2 * np.cos(ang + 0.01), 1 + 2 * np.sin(ang + 0.01), 0.0]])
    assert not in_vo_cones(cones, miss)[0, 0]
    assert in_vo_cones(cones, miss, tol=0.5)[0, 0]


def test_cone_inside_zone():
    """Inside r_pz: closing velocities (towards B, relative to V_B) are in the VO, leaving ones
    are not; the 'inside' section is the matching half-plane on every plane."""
    rng = np.random.default_rng(8)
    p_a = np.array([0.0, 0.0, 10.0])
    rel = np.array([3.0, -2.0, 1.0])
    v_b = np.array([0.5, 1.0, -0.5])
    cones = vo_cones(p_a, (p_a + rel)[None], v_b[None], 10.0, reach=REACH)
    assert cones.inside[0]
    v = rng.uniform(-REACH, REACH, (500, 3))
    got = in_vo_cones(cones, v)[0]
    closing = (v - v_b) @ rel > 0
    assert np.array_equal(got, closing)
    assert got.any() and (~got).any()
    planes = _planes(rng.normal(size=3), default_phis(15))
    sec = cone_sections(cones, planes)
    assert np.all(sec.kind_names == "inside")
    xy = _plane_samples(rng, len(planes.phi), 200)
    assert np.array_equal(sec.contains(xy)[0], _exact_on_plane(cones, planes, xy)[0])


def _brute_force_prism(pyr, v, t_max=100.0, n_t=4001):
    """Whether the sampled ray p_A + v t, t in [0, t_max], has a point strictly inside C_pz."""
    t = np.linspace(0.0, t_max, n_t)
    local = np.einsum("mij,kj->mki", pyr.frame, v)[:, :, None, :] * t[None, None, :, None]
    lo, hi = pyr.lo[:, None, None, :], pyr.hi[:, None, None, :]
    inside = np.all((local > lo) & (local < hi), axis=-1)
    first = np.where(inside.any(-1), t[np.argmax(inside, axis=-1)], np.inf)
    return inside.any(axis=-1), first, t[1] - t[0]


def _prism_exit_time(pyr, v):
    """Time the ray p_A + v t leaves C_pz (slab method), for the first pyramid: (M,)."""
    w = v @ pyr.frame[0].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = pyr.lo[0] / w, pyr.hi[0] / w
    return np.min(np.where(w == 0, np.inf, np.maximum(t1, t2)), axis=1)


def test_in_vo_pyramids_matches_sampled_rays():
    rng = np.random.default_rng(9)
    checked = hits = 0
    for _ in range(60):
        ob = _random_obstacle(rng)
        p_a = _random_outside_position(rng, ob)
        pyr = vo_pyramids(p_a, [ob])
        to_c = np.r_[ob.center - p_a[:2], ob.prism_height / 2 - p_a[2]]
        v = np.concatenate([
            _unit(rng.normal(size=(40, 3))) * rng.uniform(0.2, REACH, (40, 1)),
            (to_c + rng.normal(size=(40, 3)) * ob.side) / rng.uniform(3, 30, (40, 1)),
        ])
        got = in_vo_pyramids(pyr, v, horizon=100.0)[0]
        t_in = pyramid_entry_time(pyr, v)[0]
        sampled, first, dt = _brute_force_prism(pyr, v)
        sampled, first = sampled[0], first[0]
        # exclude rays whose membership changes under a small relative perturbation, and rays
        # whose time inside C_pz is shorter than the sampling step or entry near t = 100 s
        stable = np.ones(len(v), bool)
        for _k in range(6):
            dv = _unit(rng.normal(size=v.shape)) * 1e-3 * np.linalg.norm(v, axis=1, keepdims=True)
            stable &= in_vo_pyramids(pyr, v + dv, horizon=100.0)[0] == got
        stable &= np.abs(t_in - 100.0) > 2 * dt
        stable &= ~got | (_prism_exit_time(pyr, v) - t_in > 2 * dt)
        assert np.array_equal(got[stable], sampled[stable])
        ok = stable & got
        assert np.all(np.abs(first[ok] - t_in[ok]) <= dt + 1e-9)
        checked += stable.sum()
        hits += ok.sum()
    assert checked > 0.9 * 60 * 80 and hits > 200


def test_pyramid_covers_obstacle_and_near_face():
    """Velocities aimed at points of the obstacle are in the VO pyramid. Below h_pz the pyramid
    is exactly the paper's near-face pyramid (eqs 19–22); above h_pz the top face adds rays."""
    rng = np.random.default_rng(10)
    above_only = 0
    for _ in range(100):
        ob = _random_obstacle(rng)
        p_a = _random_outside_position(rng, ob)
        pyr = vo_pyramids(p_a, [ob])
        # points inside the obstacle
        if isinstance(ob, Cylinder):
            rr = ob.radius * np.sqrt(rng.uniform(0, 1, 50))
            aa = rng.uniform(0, 2 * np.pi, 50)
            xy = ob.center + np.stack([rr * np.cos(aa), rr * np.sin(aa)], -1)
        else:
            loc = rng.uniform(-0.5, 0.5, (50, 2)) * ob.size
            c, s = np.cos(ob.yaw), np.sin(ob.yaw)
            xy = ob.center + loc @ np.array([[c, s], [-s, c]])
        pts = np.c_[xy, rng.uniform(0, ob.height, 50)]
        assert np.all(ob.surface_distance(pts) == 0)
        v = (pts - p_a) / rng.uniform(1, 20, (50, 1))
        assert np.all(in_vo_pyramids(pyr, v)[0])
        # the near face (x = lo_h in the prism frame): does the ray cross it inside the face?
        w = _unit(rng.normal(size=(300, 3)))
        loc_w = w @ pyr.frame[0].T
        with np.errstate(divide="ignore", invalid="ignore"):
            t = pyr.lo[0, 0] / loc_w[:, 0]
        hit_pt = loc_w * t[:, None]
        face = (t > 0) & np.all((hit_pt[:, 1:] > pyr.lo[0, 1:]) & (hit_pt[:, 1:] < pyr.hi[0, 1:]), axis=1)
        exact = in_vo_pyramids(pyr, w)[0]
        nf = pyr.near_face[0]
        assert np.allclose(nf @ pyr.frame[0, 0], pyr.lo[0, 0])  # the near face's plane
        if p_a[2] < ob.prism_height and pyr.lo[0, 0] > 0:
            assert np.array_equal(exact, face)
        else:
            assert np.all(exact[face])
            above_only += (exact & ~face).sum()
    assert above_only > 0


def test_pyramid_horizon():
    ob = Cylinder(center=(23.0, 0.0), radius=3.0, height=30.0)  # L_pz = 10: near face at x = 18
    pyr = vo_pyramids(np.array([0.0, 0.0, 10.0]), [ob])
    v = np.array([[2.0, 0.0, 0.0]])  # enters at t = 9 s
    assert np.isclose(pyramid_entry_time(pyr, v)[0, 0], 9.0)
    assert in_vo_pyramids(pyr, v)[0, 0]
    assert in_vo_pyramids(pyr, v, horizon=9.5)[0, 0]
    assert not in_vo_pyramids(pyr, v, horizon=8.5)[0, 0]
    assert not in_vo_pyramids(pyr, -v)[0, 0]
    assert np.isinf(pyramid_entry_time(pyr, np.zeros((1, 3)))[0, 0])
    over = np.array([[2.0, 0.0, 3.0]])  # climbs over the 32 m prism before reaching it
    assert not in_vo_pyramids(pyr, over)[0, 0]


def test_a_ray_under_the_floor_is_no_way_past_an_obstacle():
    """An obstacle stands on the ground: a velocity whose ray would reach its footprint only
    below the ground enters C_pz (the vehicle levels off at the floor and flies into it), at the
    time its horizontal path reaches the prism's near face; over the prism it still passes."""
    ob = Cylinder(center=(23.0, 0.0), radius=3.0, height=30.0)  # L_pz = 10: near face at x = 18
    pyr = vo_pyramids(np.array([0.0, 0.0, 0.5]), [ob])
    down = np.array([[2.0, 0.0, -0.5], [2.0, 0.0, -4.0], [0.5, 0.0, -3.0]])  # under ground by x = 18
    assert np.all(in_vo_pyramids(pyr, down)[0])
    assert np.allclose(pyramid_entry_time(pyr, down)[0], 18.0 / down[:, 0])
    beside = np.array([[2.0, 2.0, -0.5]])  # its horizontal path misses the footprint
    assert not in_vo_pyramids(pyr, beside)[0, 0]
    over = np.array([[2.0, 0.0, 4.0]])  # climbs over the 32 m prism before reaching it
    assert not in_vo_pyramids(pyr, over)[0, 0]


def test_base_circle_crossings_lie_on_plane_and_circle():
    """Eqs (14)-(16): the chord angles of cone_sections are where B_vo meets the plane."""
    rng = np.random.default_rng(11)
    n = 30
    r = rng.uniform(1, 10, n)
    rel = _unit(rng.normal(size=(n, 3))) * (r * rng.uniform(1.05, 3, n))[:, None]
    v_b = rng.normal(size=(n, 3)) * 2
    cones = vo_cones(np.zeros(3), rel, v_b, r, virtual_sphere=False)
    planes = _planes(rng.normal(size=3), default_phis(15))
    chord_t = cone_sections(cones, planes).chord_t
    t1, t2 = chord_t[..., 0], chord_t[..., 1]
    ok = np.isfinite(t1)
    assert ok.any() and (~ok).any()
    for t in (t1, t2):
        for i, p in np.argwhere(ok):
            b = cones.base_points(np.array([t[i, p]]))[i, 0]  # eq. (4) at the root
            assert abs(planes.normal[p] @ b) < 1e-9  # on the plane
    # no crossing <=> the whole base circle is on one side of the plane
    tt = np.linspace(0, 2 * np.pi, 720)
    z = np.einsum("nki,pi->npk", cones.base_points(tt), planes.normal)
    both = (z.min(-1) < -1e-6) & (z.max(-1) > 1e-6)
    assert np.all(ok[both])
    assert not np.any(ok[(z.min(-1) > 1e-6) | (z.max(-1) < -1e-6)])


def test_compiled_rotations_match_eqs_6_and_8():
    """The compiled cone and plane frames are the rotation matrices of eqs (6) and (8)."""
    rng = np.random.default_rng(5)
    rel = rng.normal(size=(40, 3)) * 20
    cones = vo_cones(np.zeros(3), rel, rng.normal(size=(40, 3)), 1.0)
    assert np.allclose(cones.R, rotation_el_az(cones.theta_el, cones.psi_az), atol=1e-12)
    for direction in rng.normal(size=(10, 3)):
        planes = _planes(direction, default_phis(10))
        assert np.allclose(planes.to_plane, rotation_plane(planes.phi) @ planes.frame, atol=1e-12)


@pytest.mark.parametrize("formulation", ["plane_qp", "cone_qp", "sampled"])
def test_just_under_a_prisms_top_the_least_bad_velocity_does_not_sink(formulation):
    """A vehicle crossing a cylinder 2 mm under the top of its planning prism, too fast towards
    the centre to turn back within a step, asked to descend: no velocity it can reach escapes,
    and the least-bad one (slowest going deeper, from the side and the top together) brakes
    without sinking."""
    ob = Cylinder(center=(0.0, 0.0), radius=3.0, height=20.0)
    v_now = np.array([2.0, 0.0, 0.0])
    own = AgentState(position=(-3.5, 0.0, 0.0), velocity=v_now)
    kw = dict(preferred_velocity=(2.0, 0.0, -0.5), neighbors=[], obstacles=[ob],
              limits=Limits(speed=(0, 4), altitude=(0, 60), acceleration=2.0), dt=0.1)
    enc = prepare(own, np.zeros(3), [], [ob], kw["limits"], kw["dt"], Options())
    top = enc.vos.pyramids.h_pz[0]
    own = AgentState(position=(-3.5, 0.0, top - 0.002), velocity=v_now)
    pyr = prepare(own, np.zeros(3), [], [ob], kw["limits"], kw["dt"], Options()).vos.pyramids
    assert pyr.inside[0] and pyr.hi[0, 2] < -pyr.lo[0, 0]  # just under the top
    d = VelocitySelector(formulation).select(own=own, **kw)
    assert d.status == "infeasible_min_violation"
    assert d.velocity[0] < v_now[0] and d.velocity[2] >= 0.0


@pytest.mark.parametrize(("formulation", "solver"), [
    ("plane_qp", None), ("plane_qp", "daqp"), ("cone_qp", None), ("sampled", None), ("nlp", None)])
def test_under_a_prisms_top_answers_clear_both_ways_out_by_the_margin(formulation, solver):
    """0.3 m under a cylinder prism's top, 1 m from its axis (the top far nearer than the
    side), whatever the preferred velocity (level ones among them, which the prism's own row
    alone answers on the boundary, v_z = 0): the answer neither nears the centre nor sinks,
    each by at least the margin, as every answer clears the VOs it is outside of (the QPs hold
    both rows of the escape; the grid checks the clearance)."""
    if formulation == "nlp":
        pytest.importorskip("casadi")
    if solver == "daqp":
        pytest.importorskip("daqp")
    ob = Cylinder(center=(0.0, 0.0), radius=3.0, height=20.0)
    own = AgentState(position=(-1.0, 0.0, ob.prism_height - 0.3), velocity=np.zeros(3))
    pyr = prepare(own, np.zeros(3), [], [ob], Limits(speed=(0, 4), altitude=(0, 60)), 0.1,
                  Options()).vos.pyramids
    assert pyr.inside[0] and pyr.hi[0, 2] < -pyr.lo[0, 0]  # under the top
    selector, margin = VelocitySelector(formulation, solver), Options().margin
    rng = np.random.default_rng(3)
    level = [(-1.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.5, -0.7, 0.0)]
    for pref in [*map(np.array, level), *(rng.normal(size=(8, 3)) * (1.5, 1.5, 0.5))]:
        d = selector.select(own=own, preferred_velocity=pref, neighbors=[], obstacles=[ob],
                            limits=Limits(speed=(0, 4), altitude=(0, 60)), dt=0.1)
        assert d.status == "inside_protected_zone", pref
        assert d.velocity[0] <= -margin * (1 - 1e-6) and d.velocity[2] >= margin * (1 - 1e-6)


@pytest.mark.parametrize("formulation", ["plane_qp", "sampled"])
def test_over_a_roofs_edge_under_a_raised_top_no_answer_sinks(formulation):
    """Over a cylinder's roof, 0.5 m inside its rim and 0.5 m above it, in a prism whose top
    margin (4 m) exceeds its side margin (2 m), asked straight down: the answer does not sink
    onto the roof, though the side (gap 2.5 m) is nearer than the top (3.5 m)."""
    ob = Cylinder(center=(0.0, 0.0), radius=3.0, height=20.0, L_pz=10.0, h_pz=24.0)
    own = AgentState(position=(-2.5, 0.0, 20.5), velocity=np.zeros(3))
    limits = Limits(speed=(0, 4), altitude=(0, 60))
    pyr = prepare(own, np.zeros(3), [], [ob], limits, 0.1, Options()).vos.pyramids
    assert pyr.inside[0] and not pyr.hi[0, 2] < -pyr.lo[0, 0]  # inside, the side nearer
    assert pyr.over_roof[0]
    d = VelocitySelector(formulation).select(own=own, preferred_velocity=(0.0, 0.0, -2.0),
                                             neighbors=[], obstacles=[ob], limits=limits, dt=0.1)
    assert d.velocity[2] >= 0.0


def _roof_case(rng: np.random.Generator) -> tuple[Cylinder | Box, np.ndarray]:
    """A cylinder or a turned box whose prism's top margin (1-5 m) may exceed its side margin
    (0.5-3 m), and a point inside the prism over the roof: above the footprint, between the
    obstacle's height and the prism's top."""
    height, side, top = rng.uniform(5, 30), rng.uniform(0.5, 3), rng.uniform(1, 5)
    if rng.random() < 0.5:
        r = rng.uniform(1, 6)
        ob: Cylinder | Box = Cylinder(center=(0.0, 0.0), radius=r, height=height,
                                      L_pz=2 * (r + side), h_pz=height + top)
        xy = r * np.sqrt(rng.random()) * np.array([np.cos(a := rng.uniform(0, 2 * np.pi)),
                                                    np.sin(a)])
    else:
        size = rng.uniform(1, 10, 2)
        ob = Box(center=(0.0, 0.0), size=tuple(size), height=height, yaw=rng.uniform(0, np.pi),
                 L_pz=float(np.hypot(*size)) + 2 * side, h_pz=height + top)
        c, s = np.cos(ob.yaw), np.sin(ob.yaw)
        local = rng.uniform(-0.5, 0.5, 2) * size
        xy = np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]])
    return ob, np.array([*xy, rng.uniform(height, height + top)])


@pytest.mark.parametrize("formulation", ["plane_qp", "cone_qp", "nlp", "sampled"])
def test_over_any_roof_inside_the_prism_no_answer_sinks(formulation):
    """Anywhere over a cylinder's or a box's roof inside its prism, whichever of the prism's
    side and top is nearer, asked anywhere (down among them): the answer never sinks, and a
    vehicle counted beside the obstacle by the top-nearer rule alone is among the cases."""
    if formulation == "nlp":
        pytest.importorskip("casadi")
    rng, beside = np.random.default_rng(11), 0
    selector, limits = VelocitySelector(formulation), Limits(speed=(0, 4), altitude=(0, 60))
    for _ in range(40):
        ob, p = _roof_case(rng)
        own = AgentState(position=p, velocity=np.zeros(3))
        pyr = prepare(own, np.zeros(3), [], [ob], limits, 0.1, Options()).vos.pyramids
        assert pyr.inside[0] and pyr.over_roof[0]
        beside += not pyr.hi[0, 2] < -pyr.lo[0, 0]
        pref = rng.normal(size=3) * (2.0, 2.0, 1.0) - (0.0, 0.0, 1.0)
        d = selector.select(own=own, preferred_velocity=pref, neighbors=[], obstacles=[ob],
                            limits=limits, dt=0.1)
        assert d.velocity[2] >= 0.0, (ob, p, pref)
    assert beside >= 5


def test_prism_rows_without_a_roof_decide_as_before_off_the_roof():
    """Off the roof (past its rim, or below its height) a prism row of four columns and one of
    six give the same answer bit for bit; over the roof with the side nearer, only the six
    columns keep the vehicle from sinking."""
    rng, selector = np.random.default_rng(5), VelocitySelector()
    limits, differ = Limits(speed=(0, 4), altitude=(0, 60)), 0
    for _ in range(60):
        ob, p = _roof_case(rng)
        off = rng.random()
        if off < 0.3:  # past the rim, inside the prism
            rim, half = ob.prism[5], ob.side / 2
            p[:2] = rng.uniform(rim, half) * p[:2] / max(np.linalg.norm(p[:2]), 1e-9)
        elif off < 0.5:  # below the roof
            p[2] = rng.uniform(0.5, ob.height)
        row = np.array([ob.prism])
        pref = np.array([0.3, -0.2, -2.0])
        args = dict(position=p, velocity=np.zeros(3), preferred_velocity=pref, limits=limits,
                    dt=0.1)
        six = selector.select_arrays(obstacles=row, **args)
        four = selector.select_arrays(obstacles=row[:, :4], **args)
        over = np.linalg.norm(p[:2]) < ob.prism[5] and p[2] >= ob.height
        if not over:
            np.testing.assert_array_equal(six.velocity, four.velocity)
        else:
            assert six.velocity[2] >= 0.0
            differ += four.velocity[2] < 0.0
    assert differ >= 1


def test_select_many_over_a_roof_decides_as_select():
    """The compiled swarm path reads the prism rows' roofs as ``select`` does: vehicles over
    roofs inside their prisms, asked down, get ``select``'s answers bit for bit, none sinking."""
    rng, selector = np.random.default_rng(7), VelocitySelector()
    limits = Limits(speed=(0, 4), altitude=(0, 60))
    for _ in range(10):
        ob, p = _roof_case(rng)
        far = p + (200.0, 0.0, 0.0)  # a second vehicle out of sensing range
        pref = np.array([[0.2, 0.1, -2.0], [1.0, 0.0, 0.0]])
        many = selector.select_many(np.array([p, far]), np.zeros((2, 3)), pref, 5.0, [ob],
                                    limits, 0.1)
        one = selector.select(own=AgentState(position=p, velocity=np.zeros(3)),
                              preferred_velocity=pref[0], obstacles=[ob], limits=limits, dt=0.1)
        np.testing.assert_array_equal(many.velocities[0], one.velocity)
        assert one.velocity[2] >= 0.0
