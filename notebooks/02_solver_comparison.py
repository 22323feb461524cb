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
# # 02 — Formulations and solvers compared
#
# Every formulation (`sampled`: the paper's reference; `plane_qp`: per-plane linearised
# half-space QPs; `cone_qp`: one 3D QP with half-spaces tangent to the VO cones and pyramids;
# `nlp`: the exact non-convex problem with CasADi) × every installed QP backend (the cvxpy
# variants are slow to call, so only a few of them), on random encounters (the generator of
# `benchmarks/bench_select.py`: one head-on neighbour, so the preferred velocity is never safe)
# and on two small bundled scenarios. For each: the time per decision, the deviation from the
# preferred velocity (and its gap to `sampled` and to `nlp`), safety by an **exact** 3D check
# written in this notebook from the paper's definitions (independent of the library and of the
# formulation's own linearisation), and fallbacks (decisions whose status is not `"optimal"`).
# Only the public API is used (`VelocitySelector`, `run_scenario`, `summarize`). Timings depend
# on the machine and its load.

# %%
import importlib.util
import inspect
import platform
import warnings

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display
from nbcommon import ROOT, figure_dir, fmt, md_table, save

from vo3d_opt import VelocitySelector
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.simulator import run_scenario
from vo3d_opt.solvers import available_solvers

warnings.simplefilter("ignore")
FIGURES = figure_dir("02_solver_comparison")
spec = importlib.util.spec_from_file_location(
    "bench_select", ROOT / "benchmarks" / "bench_select.py"
)
bench_select = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench_select)
print(platform.platform(), platform.python_version())

# %% [markdown]
# ## The exact check
#
# A velocity v of vehicle A is unsafe when, everyone keeping their velocity, A would enter a
# protected zone: a neighbour's sphere of radius r_pz (the ray p_A + (v − V_B) t, t > 0, passes
# closer than r_pz to p_B: the VO cone of eqs 1–6) or an obstacle's protected prism C_pz, the
# square prism of side L_pz and height h_pz that turns a face towards A (the ray p_A + v t enters
# it: the VO pyramid of section 4).

# %%
TOL = 1e-6  # m: answers on the boundary of a zone count as safe


def enters_sphere(p_a, v, p_b, v_b, r_pz):
    rel, u = p_b - p_a, v - v_b
    uu = u @ u
    t = max(rel @ u / uu, 0.0) if uu > 0 else 0.0
    return t > 0 and np.linalg.norm(rel - u * t) < r_pz - TOL


def enters_prism(p_a, v, obstacle):
    towards = np.append(obstacle.center - p_a[:2], 0.0)
    d = np.linalg.norm(towards)
    h = towards / d
    frame = np.array([h, [-h[1], h[0], 0.0], [0.0, 0.0, 1.0]])  # h, left, up
    half = obstacle.side / 2.0
    lo = np.array([d - half, -half, -p_a[2]]) + TOL
    hi = np.array([d + half, half, obstacle.prism_height - p_a[2]]) - TOL
    w = frame @ v
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = np.where(w != 0, lo / w, -np.inf), np.where(w != 0, hi / w, np.inf)
    inside_slab = (w != 0) | ((lo < 0) & (0 < hi))
    t_in = np.max(np.minimum(t0, t1))
    t_out = np.min(np.maximum(t0, t1))
    return bool(inside_slab.all() and t_in < t_out and t_out > 0)


def unsafe(v, case):
    p = case["own"].position
    return any(
        enters_sphere(p, v, nb.position, nb.velocity, nb.r_pz) for nb in case["neighbors"]
    ) or any(enters_prism(p, v, ob) for ob in case["obstacles"])


def within_limits(v, case, tol=1e-6):
    lim, z = case["limits"], case["own"].position[2] + v[2] * case["dt"]
    return (np.linalg.norm(v) <= lim.v_max + tol) and (lim.z_min - tol <= z <= lim.z_max + tol)


# %%
CVXPY_FEW = ["cvxpy", "cvxpy:CLARABEL", "cvxpy:OSQP"]
solvers = available_solvers()
qp = [s for s in solvers if not s.startswith("casadi")]
qp_used = [s for s in qp if not s.startswith("cvxpy")] + [s for s in CVXPY_FEW if s in qp]
nlp_used = [s for s in ("casadi", "casadi:sqpmethod") if s in solvers]
combos = (
    [("sampled", None)]
    + [("plane_qp", s) for s in qp_used]
    + [("cone_qp", s) for s in qp_used if s != "exact2d"]  # exact2d: the per-plane problem only
    + [("nlp", s) for s in nlp_used]
)
print(len(combos), "combinations; QP backends used:", ", ".join(qp_used))
print("default QP solver:", VelocitySelector("plane_qp").solver)

rng = np.random.default_rng(2024)
cases = [bench_select.encounter(rng, 5, 3) for _ in range(12)] + [
    bench_select.encounter(rng, 10, 0) for _ in range(12)
]
print(len(cases), "encounters: 12 with 5 neighbours and 3 obstacles, 12 with 10 neighbours")
print(
    "preferred velocity unsafe in",
    sum(unsafe(np.asarray(c["preferred_velocity"]), c) for c in cases),
    "of them",
)

# %%
results = {}
for form, solver in combos:
    sel = VelocitySelector(form, solver=solver)
    sel.select(**cases[0])  # warm-up (solver set-up, caches), not timed
    t, dev, bad, outside, status = [], [], [], [], []
    for case in cases:
        d = sel.select(**case)
        v = np.asarray(d.velocity)
        t.append(d.solve_time * 1e6)
        dev.append(float(np.linalg.norm(v - np.asarray(case["preferred_velocity"]))))
        bad.append(unsafe(v, case))
        outside.append(not within_limits(v, case))
        status.append(d.status)
    results[(form, solver)] = dict(
        t=np.array(t),
        dev=np.array(dev),
        unsafe=np.array(bad),
        outside=np.array(outside),
        status=np.array(status),
    )
print("done")


# %%
def label(key):
    return f"{key[0]} / {key[1] or '-'}"


ref_s = results[("sampled", None)]["dev"]
ref_n = results[("nlp", nlp_used[0])]["dev"] if nlp_used else None
rows = []
for key, r in results.items():
    opt = r["status"] == "optimal"
    rows.append(
        [
            label(key),
            fmt(np.median(r["t"]), ".0f"),
            fmt(np.percentile(r["t"], 90), ".0f"),
            fmt(r["dev"].mean()),
            fmt((r["dev"] - ref_s).mean(), "+.3f"),
            fmt((r["dev"] - ref_n).mean(), "+.3f") if ref_n is not None else "—",
            int((r["unsafe"] & opt).sum()),
            int(r["unsafe"].sum()),
            int(r["outside"].sum()),
            int((~opt).sum()),
        ]
    )
display(
    md_table(
        [
            "formulation / solver",
            "median µs",
            "p90 µs",
            "mean deviation (m/s)",
            "gap to sampled",
            "gap to nlp",
            "unsafe 'optimal'",
            "unsafe (any status)",
            "outside limits",
            "fallbacks",
        ],
        rows,
    )
)

# %%
# horizontal box plots across matplotlib versions (``vert`` became ``orientation`` in 3.10)
HBOX = (
    {"orientation": "horizontal"}
    if "orientation" in inspect.signature(plt.Axes.boxplot).parameters
    else {"vert": False}
)
keys = list(results)
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(14, 0.32 * len(keys) + 1.5), sharey=True)
ax1.boxplot(
    [results[k]["t"] / 1000 for k in keys], showfliers=True, flierprops=dict(markersize=2), **HBOX
)
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
save(fig, FIGURES, "time_and_deviation")
plt.show()

# %% [markdown]
# ## On small bundled scenarios
#
# The same selectors flying whole scenarios (every agent deciding for itself each 0.2 s), judged by
# `vo3d_opt.sim.metrics.summarize`: the vertical encounter (three UAVs) and paper case 3 (two UAVs,
# two cylinders, VO pyramids).

# %%
SCENARIOS = ["vertical-encounter", "paper-case3-two-uav-two-cylinders"]
scen_combos = [
    ("sampled", None),
    ("plane_qp", None),
    ("plane_qp", "osqp"),
    ("plane_qp", "clarabel"),
    ("cone_qp", None),
    ("nlp", None),
]
rows, runs = [], {}
for name in SCENARIOS:
    for form, solver in scen_combos:
        rec = run_scenario(
            ROOT / "scenarios" / f"{name}.yaml", formulation=form, solver=solver, progress=False
        )
        s = summarize(rec)
        runs[(name, form, rec.solver)] = s
        rows.append(
            [
                name,
                form,
                rec.solver,
                s["steps"],
                f"{s['reached']}/{s['agents']}",
                fmt(s["min_vehicle_distance"]),
                fmt(s["min_obstacle_distance"]),
                s["pz_intrusions"],
                s["obstacle_pz_intrusions"],
                s["collisions"],
                s["fallbacks"],
                fmt(s["decision_time_median_us"], ".0f"),
                fmt(s["path_length_ratio"]),
            ]
        )
display(
    md_table(
        [
            "scenario",
            "formulation",
            "solver",
            "steps",
            "arrived",
            "min vehicle dist (m)",
            "min obstacle dist (m)",
            "pz intrusions",
            "prism intrusions",
            "collisions",
            "fallbacks",
            "median µs",
            "path ratio",
        ],
        rows,
    )
)

# %% [markdown]
# ## Conclusion (computed from the numbers above)

# %%
med = {k: np.median(r["t"]) for k, r in results.items()}
fastest = min(med, key=med.get)
plane = {k: v for k, v in med.items() if k[0] == "plane_qp"}
best_plane = min(plane, key=plane.get)
lines = [
    f"- Fastest combination on the random encounters: **{label(fastest)}**, "
    f"median {med[fastest]:.0f} µs per decision.",
    f"- Fastest plane_qp backend: **{best_plane[1]}** ({plane[best_plane]:.0f} µs), "
    f"{med[('sampled', None)] / plane[best_plane]:.1f}x faster than the sampled reference "
    f"({med[('sampled', None)]:.0f} µs).",
]
for form in ("plane_qp", "cone_qp", "nlp"):
    ks = [k for k in results if k[0] == form]
    if ks:
        g = np.mean([np.mean(results[k]["dev"] - ref_s) for k in ks])
        word = "closer to" if g < 0 else "further from"
        lines.append(
            f"- {form}: on average {abs(g):.3f} m/s {word} the preferred velocity than sampled "
            f"(mean over its {len(ks)} backend(s))."
        )
bad_opt = {
    label(k): int((r["unsafe"] & (r["status"] == "optimal")).sum()) for k, r in results.items()
}
n_bad = sum(bad_opt.values())
lines.append(
    f"- Decisions reported optimal yet inside a VO by the exact check: {n_bad}"
    + ("" if n_bad == 0 else f" ({', '.join(f'{k}: {v}' for k, v in bad_opt.items() if v)})")
    + "."
)
fb = {label(k): int((r["status"] != "optimal").sum()) for k, r in results.items()}
lines.append(
    f"- Fallbacks (non-optimal statuses) on the random encounters: {sum(fb.values())} of "
    f"{len(cases) * len(results)} decisions."
)
worst = max(runs.items(), key=lambda kv: kv[1]["pz_intrusions"] + kv[1]["obstacle_pz_intrusions"])
tot = sum(s["pz_intrusions"] + s["obstacle_pz_intrusions"] for s in runs.values())
lines.append(
    f"- Scenario runs: {tot} protected-zone intrusions in total over {len(runs)} runs"
    + (
        ""
        if tot == 0
        else f" (most: {worst[0]}: {worst[1]['pz_intrusions']} vehicle, "
        f"{worst[1]['obstacle_pz_intrusions']} prism)"
    )
    + "."
)
display(Markdown("\n".join(lines)))
