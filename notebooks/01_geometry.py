# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     notebook_metadata_filter: -jupytext.text_representation.jupytext_version
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 01 — The geometry of the improved 3D velocity obstacle
#
# What the selector works with (paper sections 2–4): the **VO cone** of a moving vehicle with a
# spherical protected zone (eqs 1–6, with the virtual sphere of section 3.1.6), the **VO pyramid**
# of a static cylinder or box under its tall square protected prism (section 4), the
# **avoidance planes** P_φ through the velocity origin that share the preferred-velocity axis
# (eq. 8), and the **conic sections** of a cone on a plane in all eight kinds of section 3.1
# (blank, point, line, triangle, circle, ellipse, parabola, hyperbola), drawn on their plane with
# the exact 3D membership (`vo3d_opt.geometry.in_vo_cones`) shaded behind them.

# %%
import warnings

import matplotlib.pyplot as plt
import numpy as np
from nbcommon import figure_dir, save

from vo3d_opt import Cylinder
from vo3d_opt.geometry import (
    KINDS,
    avoidance_planes,
    cone_sections,
    default_phis,
    in_vo_cones,
    in_vo_pyramids,
    pyramid_sections,
    vo_cones,
    vo_pyramids,
)

warnings.simplefilter("ignore")
FIGURES = figure_dir("01_geometry")

# %% [markdown]
# ## A VO cone in velocity space
#
# Vehicle A at (0, 0, 20) m wants to fly +x at 4 m/s; vehicle B is 30 m ahead, a little left and
# above, flying towards A. The VO cone has its apex at V_B (eq. 3) and its axis towards B; its
# half-angle is asin(r_pz / d). With `reach = v_max` the cone is lengthened by the virtual-sphere
# factor τ so that its base lies beyond every reachable velocity (section 3.1.6).

# %%
p_A, v_max = np.array([0.0, 0.0, 20.0]), 4.0
v_pref = np.array([4.0, 0.0, 0.0])
p_B, V_B, r_pz = np.array([30.0, 6.0, 24.0]), np.array([-2.0, -0.5, 0.0]), 10.0
cones = vo_cones(p_A, p_B[None], V_B[None], r_pz, reach=v_max)
print(
    f"d = {cones.d_oi[0]:.2f} m, half-angle = {np.degrees(np.arcsin(cones.sin_alpha[0])):.1f} deg, "
    f"tau = {cones.tau[0]:.2f}, d_vo = {cones.d_vo[0]:.2f} m/s, r_vo = {cones.r_vo[0]:.2f} m/s"
)
print("v_pref inside the VO:", bool(in_vo_cones(cones, v_pref[None])[0, 0]))


def cone_surface(cones, i=0, n=40):
    t = np.linspace(0, 2 * np.pi, n)
    base = cones.base_points(t)[i]  # (n, 3)
    s = np.linspace(0, 1, 2)[:, None, None]
    return cones.apex[i] + s * (base - cones.apex[i])  # (2, n, 3)


def speed_ball(ax, r, **kw):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, np.pi, 12))
    ax.plot_wireframe(r * np.cos(u) * np.sin(v), r * np.sin(u) * np.sin(v), r * np.cos(v), **kw)


def plane_patch(planes, k, half):
    g = np.linspace(-half, half, 2)
    x, y = np.meshgrid(g, g)
    pts = x[..., None] * planes.e1 + y[..., None] * planes.e2[k]
    return pts[..., 0], pts[..., 1], pts[..., 2]


fig = plt.figure(figsize=(12, 5.5))
ax = fig.add_subplot(1, 2, 1, projection="3d")
S = cone_surface(cones)
ax.plot_surface(S[..., 0], S[..., 1], S[..., 2], color="tab:red", alpha=0.25, linewidth=0)
base = cones.base_points(np.linspace(0, 2 * np.pi, 60))[0]
ax.plot(*base.T, color="tab:red", lw=1)
ax.scatter(*cones.apex[0], color="k", s=20, label="apex V_B")
speed_ball(ax, v_max, color="0.6", linewidth=0.3)
ax.quiver(0, 0, 0, *v_pref, color="tab:blue", label="preferred velocity")
ax.set_title("VO cone (red) and the speed ball |v| <= 4 m/s")
ax.set_xlabel("v_x")
ax.set_ylabel("v_y")
ax.set_zlabel("v_z")
ax.legend(loc="upper left", fontsize="small")

# the avoidance planes P_phi (every 30 deg) share the preferred-velocity axis e1
planes = avoidance_planes(v_pref, default_phis(30.0))
ax = fig.add_subplot(1, 2, 2, projection="3d")
ax.plot_surface(S[..., 0], S[..., 1], S[..., 2], color="tab:red", alpha=0.2, linewidth=0)
cmap = plt.get_cmap("viridis")
for k in range(len(planes.phi)):
    X, Y, Z = plane_patch(planes, k, 1.6 * v_max)
    ax.plot_surface(X, Y, Z, color=cmap(k / (len(planes.phi) - 1)), alpha=0.18, linewidth=0)
ax.quiver(0, 0, 0, *v_pref, color="tab:blue")
ax.set_title(f"{len(planes.phi)} avoidance planes P_phi, phi = -90..90 deg")
ax.set_xlabel("v_x")
ax.set_ylabel("v_y")
ax.set_zlabel("v_z")
lim = 1.6 * v_max
for setter in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
    setter(-lim, lim)
save(fig, FIGURES, "vo_cone_and_planes")
plt.show()

# %% [markdown]
# The cone's sections on those planes (section 3.1): each plane sees its own conic. The shaded
# region is `Sections.contains` (polygon through the curve of eq. 12, closed by the base points of
# eq. 17, plus the VO lines of section 3.1.5); the dots are velocities inside the cone by the
# exact 3D test. The circle is the speed limit; the blue cross the preferred velocity.

# %%
sec = cone_sections(cones, planes)
g = np.linspace(-6, 6, 121)
gx, gy = np.meshgrid(g, g)
xy = np.stack([gx.ravel(), gy.ravel()], axis=-1)
XY = np.broadcast_to(xy, (len(planes.phi),) + xy.shape)
inside = sec.contains(XY)[0]  # (P, M)
exact = in_vo_cones(cones, planes.lift(XY).reshape(-1, 3))[0].reshape(inside.shape)
fig, axes = plt.subplots(1, len(planes.phi), figsize=(2.6 * len(planes.phi), 2.9), sharey=True)
for k, ax in enumerate(axes):
    ax.contourf(
        gx, gy, inside[k].reshape(gx.shape), levels=[0.5, 1.5], colors=["tab:red"], alpha=0.3
    )
    e = exact[k]
    ax.plot(xy[e, 0][::3], xy[e, 1][::3], ".", color="tab:red", ms=1)
    ax.add_patch(plt.Circle((0, 0), v_max, fill=False, color="0.4"))
    ax.plot(np.linalg.norm(v_pref), 0, "bx")
    ax.set_title(f"phi = {np.degrees(planes.phi[k]):.0f}: {sec.kind_names[0, k]}", fontsize="small")
    ax.set_aspect("equal")
    ax.set_xlim(-6, 6)
    ax.set_ylim(-6, 6)
axes[0].set_ylabel("y^phi (m/s)")
fig.supxlabel("x^phi (m/s), along the preferred velocity")
save(fig, FIGURES, "cone_sections_on_planes")
plt.show()
agree = np.mean(inside == exact)
print(
    f"section membership agrees with the exact 3D test on {agree:.2%} of the grid points "
    "(differences lie on the boundary: the curve is sampled at 72 generators)"
)

# %% [markdown]
# ## A VO pyramid
#
# A static cylinder gets a tall square protected prism C_pz (side L_pz, height h_pz) that turns so
# that one face is square to the horizontal line of sight from A (section 4.1). With V_B = 0 the
# VO pyramid is the set of velocities whose ray from p_A enters C_pz; its apex is the velocity
# origin (eq. 19). Below: the cylinder, its prism, and the pyramid's edges from A through the
# prism's corners (positions relative to A, m; in velocity space the same directions).

# %%
cyl = Cylinder(center=(25.0, 6.0), radius=3.0, height=30.0)
pyr = vo_pyramids(p_A, [cyl])
corners = pyr.corners[0]  # (8, 3) relative to p_A
print(f"L_pz = {pyr.L_pz[0]:g} m, h_pz = {pyr.h_pz[0]:g} m, A inside C_pz: {bool(pyr.inside[0])}")

fig = plt.figure(figsize=(12, 5.5))
ax = fig.add_subplot(1, 2, 1, projection="3d")
th, zz = np.meshgrid(np.linspace(0, 2 * np.pi, 30), np.array([0.0, cyl.height]))
ax.plot_surface(
    cyl.center[0] + cyl.radius * np.cos(th) - p_A[0],
    cyl.center[1] + cyl.radius * np.sin(th) - p_A[1],
    zz - p_A[2],
    color="0.5",
    alpha=0.5,
    linewidth=0,
)
# a box's edges join each corner to its three nearest corners
dist = np.linalg.norm(corners[:, None] - corners[None], axis=-1)
edges = {tuple(sorted((a, int(b)))) for a in range(8) for b in np.argsort(dist[a])[1:4]}
for a, b in sorted(edges):
    ax.plot(*np.stack([corners[a], corners[b]]).T, color="tab:orange", lw=1)
far = 1.25
for c in corners:
    ax.plot([0, far * c[0]], [0, far * c[1]], [0, far * c[2]], color="tab:red", lw=0.6, alpha=0.7)
face = pyr.near_face[0]
ax.plot(*np.vstack([face, face[:1]]).T, color="tab:red", lw=2, label="near face B_vo (eqs 20-22)")
ax.scatter(0, 0, 0, color="k", s=20, label="A (apex)")
ax.set_title("VO pyramid over the protected prism C_pz")
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
ax.set_zlabel("z (m)")
ax.legend(loc="upper left", fontsize="small")

# its sections on the avoidance planes are triangles (apex at the origin), lines or points
psec = pyramid_sections(pyr, avoidance_planes(v_pref, default_phis(30.0)))
ax = fig.add_subplot(1, 2, 2)
ins = psec.contains(XY)[0]
ex = in_vo_pyramids(pyr, planes.lift(XY).reshape(-1, 3))[0].reshape(ins.shape)
k = int(np.argmin(np.abs(planes.phi)))  # the horizontal plane
ax.contourf(gx, gy, ins[k].reshape(gx.shape), levels=[0.5, 1.5], colors=["tab:orange"], alpha=0.35)
ax.plot(xy[ex[k], 0][::3], xy[ex[k], 1][::3], ".", color="tab:red", ms=1, label="exact 3D test")
ax.add_patch(plt.Circle((0, 0), v_max, fill=False, color="0.4"))
ax.plot(np.linalg.norm(v_pref), 0, "bx", label="v_pref")
ax.set_aspect("equal")
ax.set_xlim(-6, 6)
ax.set_ylim(-6, 6)
ax.set_title(f"its section on P_0: {psec.kind_names[0, k]}")
ax.set_xlabel("x^phi (m/s)")
ax.set_ylabel("y^phi (m/s)")
ax.legend(fontsize="small", loc="lower left")
fig.subplots_adjust(wspace=0.3)
save(fig, FIGURES, "vo_pyramid")
plt.show()
print(
    "kinds on the planes:",
    dict(
        zip(
            np.degrees(planes.phi).round().astype(int).tolist(),
            psec.kind_names[0].tolist(),
            strict=False,
        )
    ),
)

# %% [markdown]
# ## The eight kinds of conic section
#
# Each encounter below is built in the coordinates of one avoidance plane (x along the preferred
# velocity e1, y along e2(φ), z along the plane normal), so it reads the same whatever the
# preferred direction; the same constructions are checked in `tests/test_geometry.py`.
# `d = 30 m`, `r_pz = 10 m`, so sin α = 1/3. On each plot: the shaded section
# (`Sections.contains`), the polygon's outline, the exact 3D membership (dots), the projected apex
# A^φ (black), the base points of eq. (17) (red crosses) and the symmetry-line point H of eq. (13)
# (green plus).

# %%
S3 = 1.0 / 3.0
C3 = np.sqrt(1 - S3**2)
KIND_CASES = {  # kind: (rel = p_B - p_A, V_B), in plane coordinates
    "blank": ((0.0, 0.0, 30.0), (0.5, -0.3, 1.0)),  # apex above the plane, cone opening up
    "point": ((0.0, 0.0, 30.0), (1.0, 0.5, 0.0)),  # apex on the plane, |n.a| = 1 > sin a
    "line": ((30 * C3, 0.0, 30 * S3), (1.0, 2.0, 0.0)),  # apex on the plane, |n.a| = sin a
    "triangle": ((25.0, 5.0, 4.0), (0.0, 1.0, 0.0)),  # apex on the plane, |n.a| < sin a
    "circle": ((0.0, 0.0, 30.0), (0.5, 1.0, -1.0)),  # axis along the normal
    "ellipse": ((15.0, 0.0, 26.0), (0.0, 0.0, -1.0)),  # sin a < |n.a| < 1
    "parabola": ((30 * C3, 0.0, 30 * S3), (0.5, 0.0, -1.0)),  # |n.a| = sin a, apex off the plane
    "hyperbola": ((30.0, 0.0, 0.0), (0.0, 0.0, -1.0)),  # |n.a| < sin a, apex off the plane
}
REACH = 6.0
plane = avoidance_planes(np.array([1.0, 0.0, 0.0]), np.array([0.0]))
T = plane.to_plane[0]  # rows e1, e2, n: plane coordinates -> world is c @ T
p_a = np.array([0.0, 0.0, 20.0])

fig, axes = plt.subplots(2, 4, figsize=(16, 8.4))
found = {}
for ax, (kind, (rel, vb)) in zip(axes.ravel(), KIND_CASES.items(), strict=False):
    c = vo_cones(
        p_a, (p_a + np.asarray(rel) @ T)[None], (np.asarray(vb) @ T)[None], 10.0, reach=REACH
    )
    s = cone_sections(c, plane)
    found[kind] = str(s.kind_names[0, 0])
    poly = s.polygon[0, 0]
    poly = poly[np.isfinite(poly[:, 0])]
    pts = [s.apex[0, 0][None], poly, s.chord[0, 0]]
    pts = np.vstack([p[np.isfinite(p).all(axis=1)] for p in pts if len(p)])
    lo, hi = pts.min(axis=0) - 2.0, pts.max(axis=0) + 2.0
    half = max(hi - lo) / 2
    mid = (lo + hi) / 2
    lo, hi = mid - half, mid + half
    gx2, gy2 = np.meshgrid(np.linspace(lo[0], hi[0], 161), np.linspace(lo[1], hi[1], 161))
    q = np.stack([gx2.ravel(), gy2.ravel()], axis=-1)
    ins = s.contains(q[None])[0, 0]
    ex = in_vo_cones(c, plane.lift(q[None]).reshape(-1, 3))[0]
    if ins.any():
        ax.contourf(
            gx2, gy2, ins.reshape(gx2.shape), levels=[0.5, 1.5], colors=["tab:red"], alpha=0.25
        )
    ax.plot(q[ex, 0][::4], q[ex, 1][::4], ".", color="tab:red", ms=1)
    if len(poly) >= 3:
        ax.plot(*np.vstack([poly, poly[:1]]).T, color="tab:red", lw=1.2)
    if kind == "line":  # the plane touches the cone along one generator: its in-plane projection
        axis = plane.coords(c.axis)[0, 0, :2]
        gen = c.d_vo[0] / c.cos_alpha[0] * axis / np.linalg.norm(axis)
        ax.plot(
            [s.apex[0, 0, 0], s.apex[0, 0, 0] + gen[0]],
            [s.apex[0, 0, 1], s.apex[0, 0, 1] + gen[1]],
            color="tab:red",
            lw=2,
        )
    ax.plot(*s.apex[0, 0], "ko", ms=4)
    ch = s.chord[0, 0]
    if np.isfinite(ch).all():
        ax.plot(ch[:, 0], ch[:, 1], "rx", ms=7)
    H = s.symmetry[0, 0]
    if np.isfinite(H).all():
        ax.plot(*H, "g+", ms=9)
    note = {
        "blank": "no intersection:\nthe plane misses the cone",
        "point": "only the apex A^phi",
        "line": "tangent along one generator",
    }.get(kind)
    if note:
        ax.text(0.03, 0.97, note, transform=ax.transAxes, va="top", fontsize="small")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_title(f"{kind} (classified: {found[kind]})", fontsize="medium")
fig.supxlabel("x^phi (m/s)")
fig.supylabel("y^phi (m/s)")
plt.tight_layout()
save(fig, FIGURES, "eight_conic_sections")
plt.show()
assert found == {k: k for k in KIND_CASES}, found
print("all eight kinds classified as constructed:", sorted(found) == sorted(KINDS))

# %% [markdown]
# The blank, point and line sections have no area: a velocity on such a plane is never inside the
# VO there (apart from the boundary), so the selector may use those planes freely. The parabola and
# hyperbola are open curves in the paper's formula (eq. 12); the correction of section 3.1.4
# closes them with the base points of eq. (17) and the VO lines of section 3.1.5 cover what lies
# beyond the chord, which is why the shaded region extends past the polygon's straight edge.
