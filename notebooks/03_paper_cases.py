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
# # 03 — The paper's simulation cases and flight test
#
# The four simulation cases of section 5 and the indoor flight test of section 6, from the
# bundled `scenarios/paper-*.yaml`, flown with the default selector (`plane_qp` on its default
# QP backend, the `safe` preset), with figures like the paper's (`vo3d_opt.figures`: top view,
# 3D paths, vehicle–vehicle and vehicle–obstacle distances over time) and the paper's reported
# numbers beside ours.
#
# The paper gives no coordinates for its cases: the scenario files are our reconstructions (each
# file's description says how), so the distances are comparable in kind (is the protected zone
# kept, by how much) rather than to the millimetre. The paper's times are MATLAB times on its
# machine; only their ratio (case 3: three spheres versus one pyramid per cylinder) carries over.

# %%
import warnings

import numpy as np
from IPython.display import Image, Markdown, display
from nbcommon import ROOT, figure_dir, fmt, md_table

from vo3d_opt import VelocitySelector
from vo3d_opt.animation import write_animation
from vo3d_opt.figures import write_plots
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.simulator import run_scenario

warnings.simplefilter("ignore")
FIGURES = figure_dir("03_paper_cases")
# The figures' format: "png" shows here; "pdf" or "svg" for a paper (written, not shown).
FORMAT = "png"

# %%
CASES = {
    "paper-case1-ten-uav-crossing": {"min_vehicle_distance": 9.893},
    "paper-case2-two-uav-six-obstacles": {
        "min_vehicle_distance": 12.28,
        "min_obstacle_distance": 5.522,
    },
    "paper-case3-two-uav-two-cylinders": {"time_per_iteration_s": 0.3035},
    "paper-case3-three-spheres": {"time_per_iteration_s": 1.4530},
    "paper-case4-five-uav-six-square-obstacles": {
        "min_vehicle_distance": 10.13,
        "min_obstacle_distance": 7.931,
    },
    "paper-flight-test": {"min_obstacle_distance": 0.3521},
}
records, summaries = {}, {}
for name in CASES:
    rec = run_scenario(ROOT / "scenarios" / f"{name}.yaml", progress=False)
    records[name], summaries[name] = rec, summarize(rec)
    s = summaries[name]
    print(
        f"{name}: {s['steps']} steps ({s['time']:.1f} s simulated), "
        f"{s['reached']}/{s['agents']} arrived, wall {rec.wall_time:.1f} s"
        + ("" if s["all_reached"] else "  <- stopped before all arrived")
    )


# %% [markdown]
# ## Our numbers beside the paper's


# %%
def per_step_time(rec):
    """Mean compute time per simulation step (all agents' select() calls in that step), s."""
    t = np.nansum(np.where(rec.decided, rec.decision_times, 0.0), axis=1)
    return float(t.mean())


rows = []
for name, paper in CASES.items():
    s, rec = summaries[name], records[name]
    rows.append(
        [
            name,
            f"{s['reached']}/{s['agents']}",
            s["steps"],
            fmt(paper.get("min_vehicle_distance")),
            fmt(s["min_vehicle_distance"]),
            fmt(paper.get("min_obstacle_distance")),
            fmt(s["min_obstacle_distance"]),
            s["pz_intrusions"],
            s["obstacle_pz_intrusions"],
            s["collisions"],
            s["fallbacks"],
            fmt(paper.get("time_per_iteration_s"), ".4f"),
            fmt(per_step_time(rec), ".4f"),
        ]
    )
display(
    md_table(
        [
            "case",
            "arrived",
            "steps",
            "paper min vehicle (m)",
            "ours",
            "paper min obstacle (m)",
            "ours",
            "pz intrusions",
            "prism intrusions",
            "collisions",
            "fallbacks",
            "paper s/iteration (MATLAB)",
            "ours s/step",
        ],
        rows,
    )
)
print("r_pz:", {n: float(records[n].scenario.r_pz[0]) for n in CASES})

# %% [markdown]
# ### The `safe` preset beside the paper's own selection
#
# `VelocitySelector()` flies the `safe` preset: reciprocity (each vehicle takes half of an
# avoidance), protected zones planned two steps of flight larger, and the closing guard.
# `preset="paper"` is the selection as published, where every vehicle assumes the others keep
# their velocity; with all of them deciding at once, pairs can slide into each other's zones.

# %%
rows = []
for name in CASES:
    paper = summarize(
        run_scenario(
            ROOT / "scenarios" / f"{name}.yaml", VelocitySelector(preset="paper"), progress=False
        )
    )
    safe = summaries[name]
    rows.append(
        [
            name,
            fmt(safe["min_vehicle_distance"]),
            fmt(paper["min_vehicle_distance"]),
            safe["pz_intrusions"],
            paper["pz_intrusions"],
        ]
    )
display(
    md_table(
        ["case", "closest, safe (m)", "closest, paper (m)", "intrusions: safe", "paper"],
        rows,
    )
)

# %% [markdown]
# ### Case 3: one VO pyramid per cylinder versus three spheres
#
# The original 3D VO can only avoid spheres, so it covers each cylinder with three stacked spheres
# seen as static vehicles (Fig. 18); the improved method uses one VO pyramid (Fig. 17). The paper
# reports 0.3035 s versus 1.4530 s per iteration in MATLAB.

# %%
a, b = "paper-case3-two-uav-two-cylinders", "paper-case3-three-spheres"
ta, tb = per_step_time(records[a]), per_step_time(records[b])
ma = summaries[a]["decision_time_median_us"]
mb = summaries[b]["decision_time_median_us"]
print(
    f"paper (MATLAB): pyramid {0.3035:.4f} s, spheres {1.4530:.4f} s per iteration "
    f"-> spheres {1.4530 / 0.3035:.2f}x slower"
)
print(
    f"ours: pyramid {ta * 1e3:.2f} ms, spheres {tb * 1e3:.2f} ms per step "
    f"-> spheres {tb / ta:.2f}x "
    f"{'slower' if tb > ta else 'faster'} (median per decision {ma:.0f} vs {mb:.0f} µs)"
)
print(
    f"steps to arrive: pyramid {summaries[a]['steps']}, spheres {summaries[b]['steps']}; "
    "min distance to the real cylinders: "
    f"pyramid {fmt(summaries[a]['min_obstacle_distance'])} m, "
    f"spheres {fmt(summaries[b]['min_obstacle_distance'])} m; path length ratio "
    f"{fmt(summaries[a]['path_length_ratio'])} vs {fmt(summaries[b]['path_length_ratio'])}"
)

# %% [markdown]
# ## Figures (like the paper's Figs. 13–20 and 27–30)
#
# `write_plots` draws each run (start `o`, goal `x`, obstacles filled, their protected prisms
# dashed, the closest pair's protected spheres at its closest approach) into the folder printed
# at the top, one subfolder per case.

# %%
for name, rec in records.items():
    display(Markdown(f"### {name}"))
    for path in write_plots(rec, FIGURES / name, fmt=FORMAT):
        if path.suffix == ".png":
            display(Image(filename=str(path), width=430))
        else:
            print("wrote", path)

# %% [markdown]
# ## A replay
#
# Case 2 as an animated GIF (`vo3d run ... --out DIR --animate` writes the same): plan above
# elevation, the vehicles with their protected spheres.

# %%
gif = write_animation(
    records["paper-case2-two-uav-six-obstacles"],
    FIGURES / "paper-case2-two-uav-six-obstacles" / "animation.gif",
)
print("wrote", gif)
display(Image(filename=str(gif), width=520))
