"""The pages of ``bench_swarm.py`` (docs/results/swarm.md, and docs/results/rvo2-sphere.md for
RVO2-3D's own Sphere example), rendered from its rows: one record per (case, N, method) run
(``kind`` ``run``, the default), a failed run (``failed``) or a profile (``profile``).

Every sentence with a figure in it is computed here from the rows (or read from the scenario or
the generator it names), so that a new run writes the whole page again.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numpy as np

#: The method column, and the preset each ``ours-*`` method flies (for the findings).
PRESET = {"ours-1": "safe", "ours-all": "safe", "ours-paper": "paper", "ours-fast": "fast",
          "ours-swarm": "swarm", "ours-noguard": "safe without the closing guard",
          "ours-fine": "safe on the paper's planes", "ours-nearest": "safe, nearest fallback"}


def _fmt(x: Any, spec: str = ".1f") -> str:
    return "—" if x is None else format(x, spec)


def method_name(r: dict[str, Any]) -> str:
    t = r["threads"]
    options = r.get("options") or {}
    return {"ours-1": "vo3d_opt select_many, 1 thread",
            "ours-all": f"vo3d_opt select_many, {t} threads",
            "ours-noguard": f"vo3d_opt select_many, closing_guard off, {t} threads",
            "ours-fine": f"vo3d_opt select_many, safe on 19 planes, {t} threads",
            "ours-nearest": f"vo3d_opt select_many, least_bad_escape off, {t} threads",
            "ours-paper": f"vo3d_opt select_many, preset paper, {t} threads",
            "ours-fast": f"vo3d_opt select_many, preset fast, {t} threads",
            "ours-swarm": f"vo3d_opt select_many, preset swarm (horizon "
                          f"{options.get('horizon', 0):.3g} s), {t} threads",
            "rvo2": "RVO2-3D doStep, 1 thread"}[r["method"]]


def flown(r: dict[str, Any]) -> str:
    if r.get("capped"):
        return f"first {r['steps']} steps"
    return ("whole run" if r["steps"] < r["n_steps"] or r["all_reached"]
            else f"{r['steps']} steps (max_time)")


HEADER = ("| case | N | method | flown | decide µs/agent-step | loop µs/agent-step "
          "| loop CPU µs/agent-step | min distance / r_pz (m) | pz intrusions | collisions "
          "| arrived | last arrival (s) | fallbacks | metrics s | peak MB | load |\n"
          "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")


def table_row(r: dict[str, Any]) -> str:
    if r.get("kind") == "failed":
        return f"| {r['case']} | {r['n']} | {r['method']} | failed: {r['error']} |"
    arrive = _fmt(r["arrival_time_max"]) if r["all_reached"] else "—"
    spilled = " (spilled)" if r.get("record") == "spilled" else ""
    return (f"| {r['case']} | {r['n']} | {method_name(r)} | {flown(r)} | {_fmt(r['decide_us'])} "
            f"| {_fmt(r['loop_us'])} | {_fmt(r.get('loop_cpu_us'))} "
            f"| {_fmt(r['min_vehicle_distance'], '.2f')} / {r['r_pz']:g} | {r['pz_intrusions']} "
            f"| {r['collisions']} | {r['reached']}/{r['n']} | {arrive} "
            f"| {_fmt(r['fallbacks'], 'd')} | {r['metrics_s']:.1f} | {r['peak_mb']:.0f}{spilled} "
            f"| {r['load_start']:.1f}–{r['load_end']:.1f} |")


def profile_table(profiles: list[dict[str, Any]]) -> list[str]:
    if not profiles:
        return []
    steps = profiles[0].get("profile_steps")
    what = f"first {steps} steps" if steps else "the whole run"
    lines = ["", f"Where ours spends its time (1 thread, {what} at N = {profiles[0]['n']}, µs per "
             "agent-step):", "",
             "| case | checks | k-d tree + neighbour lists | compiled decisions | of which row "
             "building | select_many total | rest of the loop | metrics | load |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for p in profiles:
        if p.get("kind") == "failed":
            lines.append(f"| {p['case']} | failed: {p['error']} |")
            continue
        lines.append(f"| {p['case']} | {p['checks_us']:.2f} | {p['tree_us']:.2f} | "
                     f"{p['kernel_us']:.2f} | {_fmt(p['rows_us'], '.2f')} | "
                     f"{p['select_many_us']:.2f} | {p['loop_rest_us']:.2f} | "
                     f"{p['metrics_us']:.2f} | {p['load']:.1f} |")
    return lines


def _runs(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in rows if r.get("kind", "run") == "run"]


def _and(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _default(fn: Callable[..., Any], name: str) -> Any:
    return inspect.signature(fn).parameters[name].default


def _load_range(runs: list[dict[str, Any]]) -> str:
    loads = [x for r in runs for x in (r["load_start"], r["load_end"])]
    return f"{min(loads):.1f}–{max(loads):.1f}"


# ------------------------------------------------------------------ the swarm page (swap, crossing)


def _groups(runs: list[dict[str, Any]]) -> dict[tuple[str, int, str], list[dict[str, Any]]]:
    out: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for r in runs:
        out.setdefault((r["case"], r["n"], flown(r)), []).append(r)
    return out


def _group_name(key: tuple[str, int, str]) -> str:
    case, n, how = key
    return f"{case} N = {n:,} ({how})"


def intrusion_findings(runs: list[dict[str, Any]]) -> list[str]:
    """Wherever RVO2-3D lets vehicles into each other's zones: what each of ours did."""
    out = []
    for key, rs in _groups(runs).items():
        rvo2 = next((r for r in rs if r["method"] == "rvo2"), None)
        if rvo2 is None or not rvo2["pz_intrusions"]:
            continue
        ours = [f"`{PRESET[r['method']]}` {r['pz_intrusions']:,}" for r in rs
                if r["method"] in PRESET and r["method"] != "ours-1"]
        out.append(f"- {_group_name(key)}: RVO2-3D {rvo2['pz_intrusions']:,} intrusions (pairs × "
                   f"steps); ours: {', '.join(ours)}.")
    if out:
        out[:0] = ["Protected-zone intrusions where RVO2-3D has some:", ""]
    return out


def speed_finding(runs: list[dict[str, Any]]) -> list[str]:
    """The crossing's cost per agent-step on one thread at each N (constant density)."""
    one = sorted((r for r in runs if r["case"] == "crossing" and r["method"] == "ours-1"),
                 key=lambda r: r["n"])
    if len(one) < 2:
        return []
    said = [f"{r['decide_us']:.1f} µs at N = {r['n']:,}" for r in one]
    return [f"- Speed at constant density (the crossing, `safe` on one thread): {_and(said)}."]


def memory_finding(runs: list[dict[str, Any]]) -> list[str]:
    top = max(runs, key=lambda r: r["peak_mb"])
    spilled = [r for r in runs if r.get("record") == "spilled"]
    note = (f"; {len(spilled)} run{'s' if len(spilled) > 1 else ''} kept its record in a temporary "
            "file (`vo3d_opt.sim.spill`)") if spilled else ""
    return [f"- Memory: at most {top['peak_mb']:.0f} MB ({top['case']} N = {top['n']:,}, "
            f"{method_name(top)}){note}."]


def against_rvo2(runs: list[dict[str, Any]]) -> list[str]:
    """Decide time per agent-step, ours over RVO2-3D's, in a table; and where ours is faster."""
    groups = {k: rs for k, rs in _groups(runs).items() if any(r["method"] == "rvo2" for r in rs)}
    methods = [m for m in PRESET if any(r["method"] == m for r in runs)]
    if not groups or not methods:
        return []
    lines = ["", "Decide time per agent-step, ours ÷ RVO2-3D's (below 1: ours is faster; ours on "
             "every thread but `ours-1`, RVO2-3D on one):", "",
             "| case | " + " | ".join(f"{m} ({PRESET[m]})" for m in methods) + " |",
             "|---|" + "---:|" * len(methods)]
    faster: dict[str, list[str]] = {}
    for key, rs in groups.items():
        rvo2 = next(r for r in rs if r["method"] == "rvo2")["decide_us"]
        ours = {r["method"]: r["decide_us"] / rvo2 for r in rs if r["method"] in PRESET}
        lines.append(f"| {_group_name(key)} | "
                     + " | ".join(_fmt(ours.get(m), ".2f") for m in methods) + " |")
        for m, ratio in ours.items():
            if ratio < 1:
                faster.setdefault(PRESET[m] + ("" if m != "ours-1" else ", 1 thread"),
                                  []).append(_group_name(key))
    lines.append("")
    lines += [f"- `{p}` is faster than RVO2-3D in {_and(where)}." for p, where in faster.items()]
    if not faster:
        lines.append("- None of ours is faster than RVO2-3D per agent-step here.")
    return lines


def arrival_finding(runs: list[dict[str, Any]]) -> list[str]:
    whole = [r for r in runs if not r.get("capped")]
    short = [f"{_group_name((r['case'], r['n'], flown(r)))} with {method_name(r)} "
             f"({r['reached']}/{r['n']})" for r in whole if not r["all_reached"]]
    if not whole:
        return []
    if not short:
        return ["- Every agent arrives in every run flown to its end (the simulator's detours "
                "turn an agent that has hardly moved for a while)."]
    return [f"- Not every agent arrives: {'; '.join(short)}."]


def quoted(commands: str | list[str]) -> str:
    """The command (or the commands, one after the other, of an appended page) as code."""
    return ", then ".join(f"`{c}`" for c in ([commands] if isinstance(commands, str) else commands))


def swarm_intro(runs: list[dict[str, Any]], command: str | list[str]) -> list[str]:
    from vo3d_opt.generators import random_crossing_scenario, sphere_swap_scenario

    cases = dict.fromkeys(r["case"] for r in runs)
    said = []
    if "swap" in cases:
        said.append("*swap*: N agents on a sphere fly to their antipodes, every path through the "
                    f"centre (r_pz {_default(sphere_swap_scenario, 'r_pz'):g} m).")
    if "crossing" in cases:
        said.append("*crossing*: the constant-density random crossing (one agent per "
                    f"{_default(random_crossing_scenario, 'volume_per_agent'):,.0f} m³ in a slab "
                    "whose area grows with N, each flying "
                    f"{_default(random_crossing_scenario, 'distance'):g} m; r_pz "
                    f"{_default(random_crossing_scenario, 'r_pz'):g} m).")
    if "rvo2-sphere" in cases:
        said.append("*rvo2-sphere*: RVO2-3D's own Sphere example ([its page](rvo2-sphere.md)).")
    neighbours = sorted({r["max_neighbors"] for r in runs})
    horizons = sorted({r["rvo2_horizon"] for r in runs if r.get("rvo2_horizon")})
    rvo2 = ("RVO2-3D (PyPI `jt-pyrvo23d`) runs on one thread with agents of radius r_pz/2"
            + (f" and its time horizon {_and([f'{h:.3g}' for h in horizons])} s (the sensing "
               "range over twice the top speed)" if horizons else "") + ".")
    return [f"{quoted(command)}: each run its own process, every method the same scenarios in "
            "the same loop (`vo3d_opt.sim.fly`: the same preferred velocities, kinematic dynamics, "
            f"detours and metrics), at most {_and([str(k) for k in neighbours])} neighbours "
            "each.", "",
            " ".join(said), "",
            "\"decide\" is the time inside `select_many()` or RVO2-3D's `doStep()` per "
            "agent-step, \"loop\" the whole loop's wall time per agent-step, \"loop CPU\" the "
            "process's CPU time for it (both threads of a two-thread run counted; on a shared "
            "machine the wall clock also measures the others' work); \"peak MB\" the run's peak "
            f"resident memory; \"load\" the load average at its start and end. {rvo2} The `swarm` "
            "preset plans with RVO2-3D's time horizon: a velocity that would meet a zone only "
            "later is allowed, as RVO2-3D allows it; the other presets, like the paper's VO, have "
            "no horizon, so in the swap they see the meeting at the centre from the first step."]


def swarm_page(rows: list[dict[str, Any]], machine: str, command: str | list[str]) -> str:
    runs = _runs(rows)
    lines = ["# Swarms against RVO2-3D", "", machine, "", *swarm_intro(runs, command), "",
             HEADER, *(table_row(r) for r in rows if r.get("kind", "run") != "profile"),
             *profile_table([r for r in rows if r.get("kind") == "profile"])]
    if runs:
        lines += ["", "## What the runs show", "", *intrusion_findings(runs), "",
                  *speed_finding(runs), *memory_finding(runs), *arrival_finding(runs),
                  *against_rvo2(runs)]
    return "\n".join(lines)


# ------------------------------------------------------------------ RVO2-3D's Sphere example


def starting_overlaps() -> list[float]:
    """The distances of the pairs of ``rvo2-sphere-812`` that start inside each other's zone."""
    from scipy.spatial import cKDTree

    from vo3d_opt.sim.scenario import load_scenario

    sc = load_scenario("rvo2-sphere-812")
    pairs = cKDTree(sc.starts).query_pairs(float(sc.r_pz.max()), output_type="ndarray")
    return sorted(float(np.linalg.norm(sc.starts[i] - sc.starts[j])) for i, j in pairs)


def sphere_intro(runs: list[dict[str, Any]], command: str | list[str],
                 floor: list[float]) -> list[str]:
    from vo3d_opt.generators.swarms import RVO2_SPHERE, RVO2_SPHERE_LIFT
    from vo3d_opt.sim.scenario import load_scenario

    sc = load_scenario("rvo2-sphere-812")
    radius = float(np.median(np.linalg.norm(sc.starts - [0.0, 0.0, RVO2_SPHERE_LIFT], axis=1)))
    p = RVO2_SPHERE
    apart = _and([f"{d:.2f} m" for d in floor])
    return [
        "RVO2-3D's `examples/Sphere.cc` as its authors wrote it, the bundled scenario "
        f"`rvo2-sphere-812`: {sc.n_agents} agents on a sphere of radius {radius:.0f} m, each to "
        f"its antipode, time step {p['dt']:g} s, neighbour distance {p['neighbor_dist']:g} m, at "
        f"most {p['max_neighbors']} neighbours, radius {p['radius']:g} m (protected zone "
        f"{2 * p['radius']:g} m: two radii), top speed {p['max_speed']:g} m/s, preferred "
        f"{p['preferred_speed']:g} m/s; the run ends when every agent is within "
        f"{sc.goal_tolerance / p['radius']:g} radii of its goal. RVO2-3D flies with its own time "
        f"horizon of {p['time_horizon']:g} s. Every method flies it in the same loop with the "
        f"same metrics ({quoted(command)}).", "",
        f"RVO2-3D's own generator places {len(floor)} pairs of agents closer than two radii at "
        f"the start ({apart} apart): every method counts those as intrusions, so "
        f"**{len(floor)} is the floor** of the intrusion column. \"decide\" is the time in "
        "`select_many()` or `doStep()`; \"loop CPU\" the process's CPU time for the whole loop "
        "(both threads of a two-thread run counted), per agent-step: on a shared machine the "
        f"wall clock also measures the other sessions (load average {_load_range(runs)} during "
        "these runs: the load column)."]


def sphere_findings(runs: list[dict[str, Any]], floor: int) -> list[str]:
    """Who keeps the pairs apart, and what it costs against RVO2-3D."""
    by = {r["method"]: r for r in runs}
    rvo2 = by.get("rvo2")
    if rvo2 is None:
        return []
    presets = {PRESET[m]: r for m, r in by.items() if m in PRESET and m != "ours-1"}
    kept = [p for p, r in presets.items() if r["pz_intrusions"] <= floor and r["all_reached"]]
    assumes = {"paper": " (each vehicle assumes the others keep their velocity)"}
    let_in = [f"the `{p}` preset{assumes.get(p, '')} {r['pz_intrusions']:,}"
              for p, r in presets.items() if r["pz_intrusions"] > floor]
    first = (f"- RVO2-3D lets agents into each other's zones {rvo2['pz_intrusions']:,} times "
             f"(pairs × steps; the floor is {floor})" + (f"; {_and(let_in)}" if let_in else "")
             + ".")
    if kept:
        named = _and([f"`{p}`" for p in kept])
        first += (f" The {named} preset{'s' if len(kept) > 1 else ''} keep every pair apart: "
                  "only the starting overlaps, every agent home.")
    out = [first]
    cpu, home = rvo2["loop_cpu_us"], rvo2["arrival_time_max"]
    others = [presets[p] for p in kept if p != "safe"]
    if others and cpu and home:
        names = _and([f"`{PRESET[r['method']]}`" for r in others])
        ratios = _and([format(r["loop_cpu_us"] / cpu, ".2f") for r in others])
        micros = _and([format(r["loop_cpu_us"], ".1f") for r in others])
        later = _and([format(100 * (r["arrival_time_max"] / home - 1), ".1f") + " %"
                      for r in others])
        times = _and([format(r["arrival_time_max"], ".0f") + " s" for r in others])
        out.append(f"- {names} cost {ratios} times RVO2-3D's CPU time per agent-step ({micros} "
                   f"µs against {cpu:.1f}); the last agent arrives {later} later than RVO2-3D's "
                   f"({times} against {home:.0f} s).")
    safe = by.get("ours-1") or by.get("ours-all")
    if safe is not None and cpu:
        ratio = safe["loop_cpu_us"] / cpu
        verdict = ("not as fast as RVO2-3D on this example" if ratio > 1
                   else "no slower than RVO2-3D on this example")
        threads = method_name(safe).removeprefix("vo3d_opt select_many, ")
        out.append(f"- `safe` ({threads}) costs {ratio:.1f} times RVO2-3D's CPU time per "
                   f"agent-step ({safe['loop_cpu_us']:.1f} µs against {cpu:.1f}): {verdict} (see "
                   "the [swarm results](swarm.md) for the sphere swap and the crossing).")
    return out


def sphere_page(rows: list[dict[str, Any]], machine: str, command: str | list[str]) -> str:
    runs = [r for r in _runs(rows) if r["case"] == "rvo2-sphere"]
    floor = starting_overlaps()
    lines = ["# RVO2-3D's own benchmark: the Sphere example, flown by RVO2-3D and by every preset",
             "", machine, "", *sphere_intro(runs, command, floor), "", HEADER,
             *(table_row(r) for r in rows if r.get("kind", "run") != "profile")]
    findings = sphere_findings(runs, len(floor))
    if findings:
        lines += ["", "What it shows:", "", *findings]
    return "\n".join(lines)


PAGES = {"swarm": swarm_page, "rvo2-sphere": sphere_page}
