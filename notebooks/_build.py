"""Generate the notebooks of this folder (stripped: no outputs, no execution counts).

    python notebooks/_build.py            # rewrite every notebook
    python notebooks/_build.py --check    # exit 1 if a notebook differs from what this writes

Edit the cells here, not in the .ipynb files: the notebooks are committed without outputs
(tests/test_notebooks.py checks that, and runs each one top to bottom in a fresh kernel).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

SETUP = '''\
%matplotlib inline
import warnings
from pathlib import Path

import numpy as np
import matplotlib.pyplot as plt
from IPython.display import Image, Markdown, display

warnings.simplefilter("ignore")
ROOT = next(p for p in [Path.cwd(), *Path.cwd().parents] if (p / "pyproject.toml").exists())


def md_table(header, rows):
    """A markdown table (pandas is not a dependency)."""
    out = ["| " + " | ".join(map(str, header)) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(map(str, r)) + " |" for r in rows]
    return Markdown("\\n".join(out))


def fmt(x, spec=".3f"):
    return "—" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)
'''


def md(text: str):
    return new_markdown_cell(text.strip("\n"))


def code(text: str):
    cell = new_code_cell(text.strip("\n"))
    cell.outputs = []
    cell.execution_count = None
    return cell


# ============================================================================ 01 geometry

NB01 = [
    md("""
# 01 — The geometry of the improved 3D velocity obstacle

What the selector works with (paper sections 2–4): the **VO cone** of a moving vehicle with a
spherical protected zone (eqs 1–6, with the virtual sphere of section 3.1.6), the **VO pyramid**
of a static cylinder or box under its tall square protected prism (section 4), the
**avoidance planes** P_φ through the velocity origin that share the preferred-velocity axis
(eq. 8), and the **conic sections** of a cone on a plane in all eight kinds of section 3.1
(blank, point, line, triangle, circle, ellipse, parabola, hyperbola), drawn on their plane with
the exact 3D membership (`vo3d_opt.geometry.in_vo_cones`) shaded behind them.
"""),
    code(SETUP + '''
from vo3d_opt.geometry import (KINDS, avoidance_planes, cone_sections, default_phis, in_vo_cones,
                               in_vo_pyramids, pyramid_sections, vo_cones, vo_pyramids)
from vo3d_opt.geometry.pyramid import BOX_EDGES
from vo3d_opt.types import Cylinder
'''),
    md("""
## A VO cone in velocity space

Vehicle A at (0, 0, 20) m wants to fly +x at 4 m/s; vehicle B is 30 m ahead, a little left and
above, flying towards A. The VO cone has its apex at V_B (eq. 3) and its axis towards B; its
half-angle is asin(r_pz / d). With `reach = v_max` the cone is lengthened by the virtual-sphere
factor τ so that its base lies beyond every reachable velocity (section 3.1.6).
"""),
    code('''
p_A, v_max = np.array([0.0, 0.0, 20.0]), 4.0
v_pref = np.array([4.0, 0.0, 0.0])
p_B, V_B, r_pz = np.array([30.0, 6.0, 24.0]), np.array([-2.0, -0.5, 0.0]), 10.0
cones = vo_cones(p_A, p_B[None], V_B[None], r_pz, reach=v_max)
print(f"d = {cones.d_oi[0]:.2f} m, half-angle = {np.degrees(np.arcsin(cones.sin_alpha[0])):.1f} deg, "
      f"tau = {cones.tau[0]:.2f}, d_vo = {cones.d_vo[0]:.2f} m/s, r_vo = {cones.r_vo[0]:.2f} m/s")
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
ax.set_xlabel("v_x"); ax.set_ylabel("v_y"); ax.set_zlabel("v_z")
ax.legend(loc="upper left", fontsize="small")

# the avoidance planes P_phi (every 30 deg) share the preferred-velocity axis e1
planes = avoidance_planes(v_pref, default_phis(30.0))
ax = fig.add_subplot(1, 2, 2, projection="3d")
ax.plot_surface(S[..., 0], S[..., 1], S[..., 2], color="tab:red", alpha=0.2, linewidth=0)
cmap = plt.get_cmap("viridis")
for k, phi in enumerate(planes.phi):
    X, Y, Z = plane_patch(planes, k, 1.6 * v_max)
    ax.plot_surface(X, Y, Z, color=cmap(k / (len(planes.phi) - 1)), alpha=0.18, linewidth=0)
ax.quiver(0, 0, 0, *v_pref, color="tab:blue")
ax.set_title(f"{len(planes.phi)} avoidance planes P_phi, phi = -90..90 deg")
ax.set_xlabel("v_x"); ax.set_ylabel("v_y"); ax.set_zlabel("v_z")
lim = 1.6 * v_max
for setter in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
    setter(-lim, lim)
plt.show()
'''),
    md("""
The cone's sections on those planes (section 3.1): each plane sees its own conic. The shaded
region is `Sections.contains` (polygon through the curve of eq. 12, closed by the base points of
eq. 17, plus the VO lines of section 3.1.5); the dots are velocities inside the cone by the
exact 3D test. The circle is the speed limit; the blue cross the preferred velocity.
"""),
    code('''
sec = cone_sections(cones, planes)
g = np.linspace(-6, 6, 121)
gx, gy = np.meshgrid(g, g)
xy = np.stack([gx.ravel(), gy.ravel()], axis=-1)
XY = np.broadcast_to(xy, (len(planes.phi),) + xy.shape)
inside = sec.contains(XY)[0]                                   # (P, M)
exact = in_vo_cones(cones, planes.lift(XY).reshape(-1, 3))[0].reshape(inside.shape)
fig, axes = plt.subplots(1, len(planes.phi), figsize=(2.6 * len(planes.phi), 2.9), sharey=True)
for k, ax in enumerate(axes):
    ax.contourf(gx, gy, inside[k].reshape(gx.shape), levels=[0.5, 1.5], colors=["tab:red"], alpha=0.3)
    e = exact[k]
    ax.plot(xy[e, 0][::3], xy[e, 1][::3], ".", color="tab:red", ms=1)
    ax.add_patch(plt.Circle((0, 0), v_max, fill=False, color="0.4"))
    ax.plot(np.linalg.norm(v_pref), 0, "bx")
    ax.set_title(f"phi = {np.degrees(planes.phi[k]):.0f}: {sec.kind_names[0, k]}", fontsize="small")
    ax.set_aspect("equal"); ax.set_xlim(-6, 6); ax.set_ylim(-6, 6)
axes[0].set_ylabel("y^phi (m/s)")
fig.supxlabel("x^phi (m/s), along the preferred velocity")
plt.show()
agree = np.mean(inside == exact)
print(f"section membership agrees with the exact 3D test on {agree:.2%} of the grid points "
      "(differences lie on the boundary: the curve is sampled at 72 generators)")
'''),
    md("""
## A VO pyramid

A static cylinder gets a tall square protected prism C_pz (side L_pz, height h_pz) that turns so
that one face is square to the horizontal line of sight from A (section 4.1). With V_B = 0 the
VO pyramid is the set of velocities whose ray from p_A enters C_pz; its apex is the velocity
origin (eq. 19). Below: the cylinder, its prism, and the pyramid's edges from A through the
prism's corners (positions relative to A, m; in velocity space the same directions).
"""),
    code('''
cyl = Cylinder(center=(25.0, 6.0), radius=3.0, height=30.0)
pyr = vo_pyramids(p_A, [cyl])
corners = pyr.corners[0]  # (8, 3) relative to p_A
print(f"L_pz = {pyr.L_pz[0]:g} m, h_pz = {pyr.h_pz[0]:g} m, A inside C_pz: {bool(pyr.inside[0])}")

fig = plt.figure(figsize=(12, 5.5))
ax = fig.add_subplot(1, 2, 1, projection="3d")
th, zz = np.meshgrid(np.linspace(0, 2 * np.pi, 30), np.array([0.0, cyl.height]))
ax.plot_surface(cyl.center[0] + cyl.radius * np.cos(th) - p_A[0], cyl.center[1] + cyl.radius * np.sin(th) - p_A[1],
                zz - p_A[2], color="0.5", alpha=0.5, linewidth=0)
for a, b in BOX_EDGES:
    ax.plot(*np.stack([corners[a], corners[b]]).T, color="tab:orange", lw=1)
far = 1.25
for c in corners:
    ax.plot([0, far * c[0]], [0, far * c[1]], [0, far * c[2]], color="tab:red", lw=0.6, alpha=0.7)
face = pyr.near_face[0]
ax.plot(*np.vstack([face, face[:1]]).T, color="tab:red", lw=2, label="near face B_vo (eqs 20-22)")
ax.scatter(0, 0, 0, color="k", s=20, label="A (apex)")
ax.set_title("VO pyramid over the protected prism C_pz")
ax.set_xlabel("x (m)"); ax.set_ylabel("y (m)"); ax.set_zlabel("z (m)")
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
ax.set_aspect("equal"); ax.set_xlim(-6, 6); ax.set_ylim(-6, 6)
ax.set_title(f"its section on P_0: {psec.kind_names[0, k]}")
ax.set_xlabel("x^phi (m/s)"); ax.set_ylabel("y^phi (m/s)")
ax.legend(fontsize="small", loc="lower left")
fig.subplots_adjust(wspace=0.3)
plt.show()
print("kinds on the planes:", dict(zip(np.degrees(planes.phi).round().astype(int).tolist(), psec.kind_names[0].tolist())))
'''),
    md("""
## The eight kinds of conic section

Each encounter below is built in the coordinates of one avoidance plane (x along the preferred
velocity e1, y along e2(φ), z along the plane normal), so it reads the same whatever the
preferred direction; the same constructions are checked in `tests/test_geometry.py`.
`d = 30 m`, `r_pz = 10 m`, so sin α = 1/3. On each plot: the shaded section
(`Sections.contains`), the polygon's outline, the exact 3D membership (dots), the projected apex
A^φ (black), the base points of eq. (17) (red crosses) and the symmetry-line point H of eq. (13)
(green plus).
"""),
    code('''
S3 = 1.0 / 3.0
C3 = np.sqrt(1 - S3**2)
KIND_CASES = {  # kind: (rel = p_B - p_A, V_B), in plane coordinates
    "blank": ((0.0, 0.0, 30.0), (0.5, -0.3, 1.0)),       # apex above the plane, cone opening up
    "point": ((0.0, 0.0, 30.0), (1.0, 0.5, 0.0)),        # apex on the plane, |n.a| = 1 > sin a
    "line": ((30 * C3, 0.0, 30 * S3), (1.0, 2.0, 0.0)),  # apex on the plane, |n.a| = sin a
    "triangle": ((25.0, 5.0, 4.0), (0.0, 1.0, 0.0)),     # apex on the plane, |n.a| < sin a
    "circle": ((0.0, 0.0, 30.0), (0.5, 1.0, -1.0)),      # axis along the normal
    "ellipse": ((15.0, 0.0, 26.0), (0.0, 0.0, -1.0)),    # sin a < |n.a| < 1
    "parabola": ((30 * C3, 0.0, 30 * S3), (0.5, 0.0, -1.0)),  # |n.a| = sin a, apex off the plane
    "hyperbola": ((30.0, 0.0, 0.0), (0.0, 0.0, -1.0)),   # |n.a| < sin a, apex off the plane
}
REACH = 6.0
plane = avoidance_planes(np.array([1.0, 0.0, 0.0]), np.array([0.0]))
T = plane.to_plane[0]  # rows e1, e2, n: plane coordinates -> world is c @ T
p_a = np.array([0.0, 0.0, 20.0])

fig, axes = plt.subplots(2, 4, figsize=(16, 8.4))
found = {}
for ax, (kind, (rel, vb)) in zip(axes.ravel(), KIND_CASES.items()):
    c = vo_cones(p_a, (p_a + np.asarray(rel) @ T)[None], (np.asarray(vb) @ T)[None], 10.0, reach=REACH)
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
        ax.contourf(gx2, gy2, ins.reshape(gx2.shape), levels=[0.5, 1.5], colors=["tab:red"], alpha=0.25)
    ax.plot(q[ex, 0][::4], q[ex, 1][::4], ".", color="tab:red", ms=1)
    if len(poly) >= 3:
        ax.plot(*np.vstack([poly, poly[:1]]).T, color="tab:red", lw=1.2)
    if kind == "line":  # the plane touches the cone along one generator: its in-plane projection
        axis = plane.coords(c.axis)[0, 0, :2]
        gen = c.d_vo[0] / c.cos_alpha[0] * axis / np.linalg.norm(axis)
        ax.plot([s.apex[0, 0, 0], s.apex[0, 0, 0] + gen[0]], [s.apex[0, 0, 1], s.apex[0, 0, 1] + gen[1]],
                color="tab:red", lw=2)
    ax.plot(*s.apex[0, 0], "ko", ms=4)
    ch = s.chord[0, 0]
    if np.isfinite(ch).all():
        ax.plot(ch[:, 0], ch[:, 1], "rx", ms=7)
    H = s.symmetry[0, 0]
    if np.isfinite(H).all():
        ax.plot(*H, "g+", ms=9)
    note = {"blank": "no intersection:\\nthe plane misses the cone", "point": "only the apex A^phi",
            "line": "tangent along one generator"}.get(kind)
    if note:
        ax.text(0.03, 0.97, note, transform=ax.transAxes, va="top", fontsize="small")
    ax.set_xlim(lo[0], hi[0]); ax.set_ylim(lo[1], hi[1]); ax.set_aspect("equal")
    ax.set_title(f"{kind} (classified: {found[kind]})", fontsize="medium")
fig.supxlabel("x^phi (m/s)"); fig.supylabel("y^phi (m/s)")
plt.tight_layout()
plt.show()
assert found == {k: k for k in KIND_CASES}, found
print("all eight kinds classified as constructed:", sorted(found) == sorted(KINDS))
'''),
    md("""
The blank, point and line sections have no area: a velocity on such a plane is never inside the
VO there (apart from the boundary), so the selector may use those planes freely. The parabola and
hyperbola are open curves in the paper's formula (eq. 12); the correction of section 3.1.4
closes them with the base points of eq. (17) and the VO lines of section 3.1.5 cover what lies
beyond the chord, which is why the shaded region extends past the polygon's straight edge.
"""),
]


# ============================================================================ 02 solvers

NB02 = [
    md("""
# 02 — Formulations and solvers compared

Every formulation (`sampled`: the paper's reference; `plane_qp`: per-plane linearised
half-space QPs; `cone_qp`: one 3D QP with half-spaces tangent to the VO cones and pyramids;
`nlp`: the exact non-convex problem with CasADi) × every installed QP backend (the cvxpy
variants are slow to call, so only a few of them), on random encounters (the generator of
`benchmarks/bench_select.py`: one head-on neighbour, so the preferred velocity is never safe)
and on two small bundled scenarios. For each: the time per decision, the deviation from the
preferred velocity (and its gap to `sampled` and to `nlp`), safety by the **exact** 3D check
(`prepare(...).unsafe`, independent of the formulation's own linearisation), and fallbacks
(decisions whose status is not `"optimal"`). Timings depend on the machine and its load.
"""),
    code(SETUP + '''
import importlib.util
import platform

from vo3d_opt import VelocitySelector
from vo3d_opt.formulations.common import Options, prepare
from vo3d_opt.selector import DEFAULT_QP_SOLVER
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.simulator import run_scenario
from vo3d_opt.solvers import available_qp_solvers, available_solvers

spec = importlib.util.spec_from_file_location("bench_select", ROOT / "benchmarks" / "bench_select.py")
bench_select = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench_select)
print(platform.platform(), platform.python_version())
'''),
    code('''
CVXPY_FEW = ["cvxpy", "cvxpy:CLARABEL", "cvxpy:OSQP"]
qp = available_qp_solvers()
qp_used = [s for s in qp if not s.startswith("cvxpy")] + [s for s in CVXPY_FEW if s in qp]
nlp_used = [s for s in ("casadi", "casadi:sqpmethod") if s in available_solvers()]
combos = ([("sampled", None)] + [("plane_qp", s) for s in qp_used] + [("cone_qp", s) for s in qp_used]
          + [("nlp", s) for s in nlp_used])
print(len(combos), "combinations; QP backends used:", ", ".join(qp_used))
print("default QP solver:", DEFAULT_QP_SOLVER)

rng = np.random.default_rng(2024)
cases = ([bench_select.encounter(rng, 5, 3) for _ in range(12)]
         + [bench_select.encounter(rng, 10, 0) for _ in range(12)])
encs = [prepare(kw["own"], np.asarray(kw["preferred_velocity"], dtype=float), kw["neighbors"],
                kw["obstacles"], kw["limits"], kw["dt"], Options()) for kw in cases]
print(len(cases), "encounters: 12 with 5 neighbours and 3 obstacles, 12 with 10 neighbours")
'''),
    code('''
results = {}
for form, solver in combos:
    sel = VelocitySelector(form, solver=solver)
    sel.select(**cases[0])  # warm-up (solver set-up, caches), not timed
    t, dev, unsafe, outside, status = [], [], [], [], []
    for kw, enc in zip(cases, encs):
        d = sel.select(**kw)
        v = np.asarray(d.velocity)
        t.append(d.solve_time * 1e6)
        dev.append(float(enc.deviation(v)[0]))
        unsafe.append(bool(enc.unsafe(v)[0]))
        outside.append(not bool(enc.within_limits(v)[0]))
        status.append(d.status)
    results[(form, solver)] = dict(t=np.array(t), dev=np.array(dev), unsafe=np.array(unsafe),
                                   outside=np.array(outside), status=np.array(status))
print("done")
'''),
    code('''
def label(key):
    return f"{key[0]} / {key[1] or '-'}"


ref_s = results[("sampled", None)]["dev"]
ref_n = results[("nlp", nlp_used[0])]["dev"] if nlp_used else None
rows = []
for key, r in results.items():
    opt = r["status"] == "optimal"
    rows.append([label(key), fmt(np.median(r["t"]), ".0f"), fmt(np.percentile(r["t"], 90), ".0f"),
                 fmt(r["dev"].mean()), fmt((r["dev"] - ref_s).mean(), "+.3f"),
                 fmt((r["dev"] - ref_n).mean(), "+.3f") if ref_n is not None else "—",
                 int((r["unsafe"] & opt).sum()), int(r["unsafe"].sum()), int(r["outside"].sum()),
                 int((~opt).sum())])
display(md_table(["formulation / solver", "median µs", "p90 µs", "mean deviation (m/s)",
                  "gap to sampled", "gap to nlp", "unsafe 'optimal'", "unsafe (any status)",
                  "outside limits", "fallbacks"], rows))
'''),
    code('''
import inspect

# horizontal box plots across matplotlib versions (``vert`` became ``orientation`` in 3.10)
HBOX = ({"orientation": "horizontal"} if "orientation" in inspect.signature(plt.Axes.boxplot).parameters
        else {"vert": False})
keys = list(results)
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(14, 0.32 * len(keys) + 1.5), sharey=True)
ax1.boxplot([results[k]["t"] / 1000 for k in keys], showfliers=True, flierprops=dict(markersize=2), **HBOX)
ax1.set_yticks(range(1, len(keys) + 1), [label(k) for k in keys])
ax1.set_xscale("log")
ax1.set_xlabel("time per decision (ms, log scale)")
ax1.grid(True, axis="x", alpha=0.4)
gaps = [results[k]["dev"] - ref_s for k in keys]
ax2.boxplot(gaps, showfliers=True, flierprops=dict(markersize=2), **HBOX)
ax2.axvline(0, color="k", lw=0.8)
ax2.set_xlabel("deviation minus sampled's (m/s): < 0 is closer to the preferred velocity")
ax2.grid(True, axis="x", alpha=0.4)
ax1.invert_yaxis()
plt.tight_layout()
plt.show()
'''),
    md("""
## On small bundled scenarios

The same selectors flying whole scenarios (every agent deciding for itself each 0.2 s), judged by
`vo3d_opt.sim.metrics.summarize`: the vertical encounter (three UAVs) and paper case 3 (two UAVs,
two cylinders, VO pyramids).
"""),
    code('''
SCENARIOS = ["vertical-encounter", "paper-case3-two-uav-two-cylinders"]
scen_combos = [("sampled", None), ("plane_qp", None), ("plane_qp", "osqp"), ("plane_qp", "clarabel"),
               ("cone_qp", None), ("nlp", None)]
rows, runs = [], {}
for name in SCENARIOS:
    for form, solver in scen_combos:
        rec = run_scenario(ROOT / "scenarios" / f"{name}.yaml", formulation=form, solver=solver, progress=False)
        s = summarize(rec)
        runs[(name, form, rec.solver)] = s
        rows.append([name, form, rec.solver, s["steps"], f"{s['reached']}/{s['agents']}",
                     fmt(s["min_vehicle_distance"]), fmt(s["min_obstacle_distance"]), s["pz_intrusions"],
                     s["obstacle_pz_intrusions"], s["collisions"], s["fallbacks"],
                     fmt(s["decision_time_median_us"], ".0f"), fmt(s["path_length_ratio"])])
display(md_table(["scenario", "formulation", "solver", "steps", "arrived", "min vehicle dist (m)",
                  "min obstacle dist (m)", "pz intrusions", "prism intrusions", "collisions",
                  "fallbacks", "median µs", "path ratio"], rows))
'''),
    md("## Conclusion (computed from the numbers above)"),
    code('''
med = {k: np.median(r["t"]) for k, r in results.items()}
fastest = min(med, key=med.get)
plane = {k: v for k, v in med.items() if k[0] == "plane_qp"}
best_plane = min(plane, key=plane.get)
lines = [f"- Fastest combination on the random encounters: **{label(fastest)}**, median {med[fastest]:.0f} µs per decision.",
         f"- Fastest plane_qp backend: **{best_plane[1]}** ({plane[best_plane]:.0f} µs), "
         f"{med[('sampled', None)] / plane[best_plane]:.1f}x faster than the sampled reference "
         f"({med[('sampled', None)]:.0f} µs)."]
for form in ("plane_qp", "cone_qp", "nlp"):
    ks = [k for k in results if k[0] == form]
    if ks:
        g = np.mean([np.mean(results[k]["dev"] - ref_s) for k in ks])
        word = "closer to" if g < 0 else "further from"
        lines.append(f"- {form}: on average {abs(g):.3f} m/s {word} the preferred velocity than sampled "
                     f"(mean over its {len(ks)} backend(s)).")
bad_opt = {label(k): int((r["unsafe"] & (r["status"] == "optimal")).sum()) for k, r in results.items()}
n_bad = sum(bad_opt.values())
lines.append(f"- Decisions reported optimal yet inside a VO by the exact check: {n_bad}"
             + ("" if n_bad == 0 else f" ({', '.join(f'{k}: {v}' for k, v in bad_opt.items() if v)})") + ".")
fb = {label(k): int((r["status"] != "optimal").sum()) for k, r in results.items()}
lines.append(f"- Fallbacks (non-optimal statuses) on the random encounters: {sum(fb.values())} of "
             f"{len(cases) * len(results)} decisions.")
worst = max(runs.items(), key=lambda kv: kv[1]["pz_intrusions"] + kv[1]["obstacle_pz_intrusions"])
tot = sum(s["pz_intrusions"] + s["obstacle_pz_intrusions"] for s in runs.values())
lines.append(f"- Scenario runs: {tot} protected-zone intrusions in total over {len(runs)} runs"
             + ("" if tot == 0 else f" (most: {worst[0]}: {worst[1]['pz_intrusions']} vehicle, "
                                   f"{worst[1]['obstacle_pz_intrusions']} prism)") + ".")
display(Markdown("\\n".join(lines)))
'''),
]


# ============================================================================ 03 paper cases

NB03 = [
    md("""
# 03 — The paper's simulation cases and flight test

The four simulation cases of section 5 and the indoor flight test of section 6, from the
bundled `scenarios/paper-*.yaml`, flown with the default selector (`plane_qp`, default QP
backend), with figures like the paper's (`vo3d_opt.plots`: top view, 3D paths, vehicle–vehicle
and vehicle–obstacle distances over time) and the paper's reported numbers beside ours.

The paper gives no coordinates for its cases: the scenario files are our reconstructions (each
file's description says how), so the distances are comparable in kind (is the protected zone
kept, by how much) rather than to the millimetre. The paper's times are MATLAB times on its
machine; only their ratio (case 3: three spheres versus one pyramid per cylinder) carries over.
"""),
    code(SETUP + '''
import tempfile

from vo3d_opt.plots import write_plots
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import load_scenario
from vo3d_opt.sim.simulator import run_scenario

OUT = Path(tempfile.mkdtemp(prefix="vo3d_paper_"))
# Set a number (s) to shorten every case when the notebook must run faster; None = full cases.
MAX_TIME = None
'''),
    code('''
CASES = {
    "paper-case1-ten-uav-crossing": {"min_vehicle_distance": 9.893},
    "paper-case2-two-uav-six-obstacles": {"min_vehicle_distance": 12.28, "min_obstacle_distance": 5.522},
    "paper-case3-two-uav-two-cylinders": {"time_per_iteration_s": 0.3035},
    "paper-case3-three-spheres": {"time_per_iteration_s": 1.4530},
    "paper-case4-five-uav-six-square-obstacles": {"min_vehicle_distance": 10.13, "min_obstacle_distance": 7.931},
    "paper-flight-test": {"min_obstacle_distance": 0.3521},
}
records, summaries = {}, {}
for name in CASES:
    sc = load_scenario(ROOT / "scenarios" / f"{name}.yaml")
    if MAX_TIME is not None and sc.max_time > MAX_TIME:
        sc = sc.model_copy(update={"max_time": float(MAX_TIME)})
    rec = run_scenario(sc, progress=False)
    records[name], summaries[name] = rec, summarize(rec)
    s = summaries[name]
    print(f"{name}: {s['steps']} steps ({s['time']:.1f} s simulated), {s['reached']}/{s['agents']} arrived, "
          f"wall {rec.wall_time:.1f} s" + ("" if s["all_reached"] else "  <- stopped before all arrived"))
'''),
    md("## Our numbers beside the paper's"),
    code('''
def per_step_time(rec):
    """Mean compute time per simulation step (all agents' select() calls in that step), s."""
    t = np.nansum(np.where(rec.decided, rec.decision_times, 0.0), axis=1)
    return float(t.mean())


rows = []
for name, paper in CASES.items():
    s, rec = summaries[name], records[name]
    rows.append([name, f"{s['reached']}/{s['agents']}", s["steps"],
                 fmt(paper.get("min_vehicle_distance")), fmt(s["min_vehicle_distance"]),
                 fmt(paper.get("min_obstacle_distance")), fmt(s["min_obstacle_distance"]),
                 s["pz_intrusions"], s["obstacle_pz_intrusions"], s["collisions"], s["fallbacks"],
                 fmt(paper.get("time_per_iteration_s"), ".4f"), fmt(per_step_time(rec), ".4f")])
display(md_table(["case", "arrived", "steps", "paper min vehicle (m)", "ours", "paper min obstacle (m)",
                  "ours", "pz intrusions", "prism intrusions", "collisions", "fallbacks",
                  "paper s/iteration (MATLAB)", "ours s/step"], rows))
print("r_pz:", {n: float(records[n].scenario.r_pz[0]) for n in CASES})
'''),
    md("""
### Case 3: one VO pyramid per cylinder versus three spheres

The original 3D VO can only avoid spheres, so it covers each cylinder with three stacked spheres
seen as static vehicles (Fig. 18); the improved method uses one VO pyramid (Fig. 17). The paper
reports 0.3035 s versus 1.4530 s per iteration in MATLAB.
"""),
    code('''
a, b = "paper-case3-two-uav-two-cylinders", "paper-case3-three-spheres"
ta, tb = per_step_time(records[a]), per_step_time(records[b])
ma = summaries[a]["decision_time_median_us"]
mb = summaries[b]["decision_time_median_us"]
print(f"paper (MATLAB): pyramid {0.3035:.4f} s, spheres {1.4530:.4f} s per iteration -> spheres {1.4530 / 0.3035:.2f}x slower")
print(f"ours: pyramid {ta * 1e3:.2f} ms, spheres {tb * 1e3:.2f} ms per step -> spheres {tb / ta:.2f}x "
      f"{'slower' if tb > ta else 'faster'} (median per decision {ma:.0f} vs {mb:.0f} µs)")
print(f"steps to arrive: pyramid {summaries[a]['steps']}, spheres {summaries[b]['steps']}; "
      f"min distance to the real cylinders: pyramid {fmt(summaries[a]['min_obstacle_distance'])} m, "
      f"spheres {fmt(summaries[b]['min_obstacle_distance'])} m; path length ratio "
      f"{fmt(summaries[a]['path_length_ratio'])} vs {fmt(summaries[b]['path_length_ratio'])}")
'''),
    md("## Figures (like the paper's Figs. 13–20 and 27–30)"),
    code('''
for name, rec in records.items():
    display(Markdown(f"### {name}"))
    paths = write_plots(rec, OUT / name)
    for p in paths:
        display(Image(filename=str(p), width=430))
'''),
    code('''
import shutil

shutil.rmtree(OUT, ignore_errors=True)  # the images are embedded above: drop the PNG files
'''),
]


# ============================================================================ 04 RVO2-3D

NB04 = [
    md("""
# 04 — RVO2-3D baseline

The agent-only scenarios flown by RVO2-3D (reciprocal velocity obstacles in 3D, van den Berg et
al.; Python binding `rvo23d` of the optional `baselines` extra) and by vo3d_opt (`plane_qp`,
default QP backend), with the same preferred-velocity rule, the same dt and speed bound, and the
same metrics (`vo3d_opt.sim.metrics`). RVO2 parameters (see `vo3d_opt/baselines/rvo2.py`): agent
radius r_pz/2, so that a pair keeps r_pz apart as our protected zone demands; neighbour distance
= the sensing range; every other agent as a neighbour; time horizon = range / (2 v_max).
RVO2-3D has no altitude limits (it flies freely in 3D; violations would show in the table) and
computes in single precision. "Compute" is the time inside `select()` per decision for us, and
the time of `doStep()` shared among the agents that moved for RVO2.
"""),
    code(SETUP + '''
import os

from vo3d_opt.baselines.rvo2 import run_rvo2, summarize_record, summarize_rvo2
from vo3d_opt.sim.metrics import nearest_vehicle_distance
from vo3d_opt.sim.scenario import load_scenario
from vo3d_opt.sim.simulator import run_scenario

SCENARIOS = ["paper-case1-ten-uav-crossing", "sphere-swap-16", "vertical-encounter"]
# random-crossing-50 takes a minute or two with our selector: set VO3D_NB_FULL=1 to include it
if os.environ.get("VO3D_NB_FULL"):
    SCENARIOS.append("random-crossing-50")
'''),
    code('''
runs = {}
for name in SCENARIOS:
    sc = load_scenario(ROOT / "scenarios" / f"{name}.yaml")
    ours = run_scenario(sc, formulation="plane_qp", progress=False)
    rvo = run_rvo2(sc)
    runs[name] = {"vo3d_opt": (ours, summarize_record(ours)), "RVO2-3D": (rvo, summarize_rvo2(rvo))}
    print(f"{name}: vo3d_opt {ours.wall_time:.1f} s wall, RVO2-3D {rvo.wall_time:.2f} s wall")
'''),
    code('''
METRICS = [
    ("agents", "agents", "d"),
    ("steps", "steps", "d"),
    ("min vehicle distance (m)", "min_vehicle_distance", ".4f"),
    ("pz intrusions (pairs)", "pz_intrusions", "d"),
    ("collisions", "collisions", "d"),
    ("altitude violations", "altitude_violations", "d"),
    ("speed violations", "speed_violations", "d"),
    ("arrived", "reached", "d"),
    ("last arrival (s)", "arrival_time_max", ".1f"),
    ("path length ratio", "path_length_ratio", ".3f"),
    ("fallbacks", "fallbacks", "d"),
    ("compute µs / agent-step (mean)", "compute_time_per_agent_step_us", ".1f"),
    ("compute µs / agent-step (median)", "decision_time_median_us", ".1f"),
]
header = ["metric"] + [f"{n}: {m}" for n in runs for m in runs[n]]
rows = []
for title, key, spec in METRICS:
    rows.append([title] + [fmt(runs[n][m][1][key], spec) for n in runs for m in runs[n]])
display(md_table(header, rows))
'''),
    code('''
fig, axes = plt.subplots(1, len(runs), figsize=(5.2 * len(runs), 3.8), squeeze=False)
for ax, (name, pair) in zip(axes[0], runs.items()):
    for (method, (rec, s)), color in zip(pair.items(), ("tab:blue", "tab:red")):
        d = nearest_vehicle_distance(rec).min(axis=1)
        ax.plot(rec.times, d, color=color, label=f"{method} (min {s['min_vehicle_distance']:.3f} m)")
    r = float(pair["vo3d_opt"][0].scenario.r_pz[0])
    ax.axhline(r, color="k", ls="--", lw=0.8, label=f"r_pz = {r:g} m")
    ax.set_ylim(0, None)
    ax.set_title(name, fontsize="medium")
    ax.set_xlabel("time (s)")
    ax.legend(fontsize="small")
axes[0, 0].set_ylabel("closest pair distance (m)")
plt.tight_layout()
plt.show()
'''),
    code('''
name = "sphere-swap-16"
fig = plt.figure(figsize=(12, 5.5))
for k, (method, (rec, s)) in enumerate(runs[name].items()):
    ax = fig.add_subplot(1, 2, k + 1, projection="3d")
    p = rec.positions
    for i in range(rec.n_agents):
        ax.plot(p[:, i, 0], p[:, i, 1], p[:, i, 2], lw=1)
    ax.set_title(f"{name}: {method}")
    ax.set_xlabel("x (m)"); ax.set_ylabel("y (m)"); ax.set_zlabel("z (m)")
plt.show()
'''),
    md("## Summary (computed from the numbers above)"),
    code('''
lines = []
for name, pair in runs.items():
    (ro, so), (rr, sr) = pair["vo3d_opt"], pair["RVO2-3D"]
    r = float(ro.scenario.r_pz.max())
    depth_o = max(0.0, r - so["min_vehicle_distance"])
    depth_r = max(0.0, r - sr["min_vehicle_distance"])
    speed = sr["compute_time_per_agent_step_us"] and so["compute_time_per_agent_step_us"] / sr["compute_time_per_agent_step_us"]
    arr = lambda s: f"{s['reached']}/{s['agents']} arrived" + (f" by {s['arrival_time_max']:.1f} s" if s["all_reached"] else "")
    pz = lambda s, depth: f"{s['pz_intrusions']} intrusions" + (f" (deepest {depth * 1000:.3g} mm)" if s["pz_intrusions"] else "")
    lines.append(
        f"- **{name}**: vo3d_opt {pz(so, depth_o)}, min distance {so['min_vehicle_distance']:.4f} m, {arr(so)}; "
        f"RVO2-3D {pz(sr, depth_r)}, min distance {sr['min_vehicle_distance']:.4f} m, {arr(sr)}; "
        f"RVO2-3D computes {speed:.0f}x faster per agent-step.")
display(Markdown("\\n".join(lines)))
'''),
    md("""
Both methods are judged by the same rule: a pair intrudes when it comes closer than r_pz − 1 µm.
RVO2-3D's agents are spheres of radius r_pz/2 that may just touch while they squeeze past each
other, and it computes in single precision, so the depth printed above tells such grazes from
real intrusions. The larger sphere swaps (100 and 1000 agents) are in `benchmarks/bench_rvo2.py`.
"""),
]


NOTEBOOKS = {
    "01_geometry.ipynb": NB01,
    "02_solver_comparison.ipynb": NB02,
    "03_paper_cases.ipynb": NB03,
    "04_rvo2_3d_baseline.ipynb": NB04,
}


def build(cells) -> nbformat.NotebookNode:
    nb = new_notebook(cells=cells)
    nb.metadata = {
        "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
        "language_info": {"name": "python"},
    }
    for i, cell in enumerate(nb.cells):
        cell["id"] = f"cell-{i:02d}"
    return nb


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check the files are up to date")
    args = ap.parse_args(argv)
    stale = []
    for name, cells in NOTEBOOKS.items():
        nb = build(cells)
        nbformat.validate(nb)
        text = nbformat.writes(nb) + "\n"
        path = HERE / name
        if args.check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(name)
        else:
            path.write_text(text, encoding="utf-8")
            print("wrote", path)
    if stale:
        print("out of date:", ", ".join(stale), "(run python notebooks/_build.py)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
