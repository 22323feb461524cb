"""The page of ``bench_real_world.py`` (docs/results/real-world.md and real-world-swarm.md),
rendered from its rows: one record per (condition, scenario) run, and the RotorPy cost notes.

Every sentence with a figure in it is computed here from the rows, so that a new run writes
the whole page again.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from paper_cases import PAPER

#: The paper's cases as the RotorPy table names them.
PAPER_LABELS = {
    "paper-case1-ten-uav-crossing": "1: ten UAVs crossing",
    "paper-case2-two-uav-six-obstacles": "2: two UAVs, six obstacles",
    "paper-case3-two-uav-two-cylinders": "3: two cylinders, VO pyramids",
    "paper-case3-three-spheres": "3: each cylinder as three spheres",
    "paper-case4-five-uav-six-square-obstacles": "4: five UAVs, six square obstacles",
    "paper-flight-test": "flight test (6 m room, 1 pole)",
}
#: The RotorPy conditions of the paper's table, and the vehicle each flies.
ROTORPY_VEHICLES = {"rotorpy hummingbird": "hummingbird", "rotorpy crazyflie": "crazyflie"}
IDEAL = "ideal (kinematic)"
MARGINS_OFF = ", margins off"
#: The event counts of a row: all zero in a clean run.
EVENTS = ("collisions", "pz_intrusions", "obstacle_pz_intrusions", "altitude_violations",
          "speed_violations")
EVENT_NAMES = {"collisions": "collision", "pz_intrusions": "protected-zone intrusion",
               "obstacle_pz_intrusions": "obstacle-prism intrusion",
               "altitude_violations": "altitude violation", "speed_violations": "speed violation"}

COSTS = ("Cost columns: path length ratio and latest arrival against the same scenario under "
         "ideal kinematics (1.000 = no cost). Margins: what the simulator derived "
         "(`vo3d_opt/sim/safety.py`, [real-world margins](../formulations/real_world.md)); "
         "\"margins off\": no acceleration bound, no altitude or obstacle margin, the pz_buffer "
         "of ideal kinematics (2 v_max dt).")
HEADER = ("| condition | scenario | arrived | collisions | pz intrusions | "
          "obstacle pz intrusions | "
          "altitude violations | speed violations | min vehicle dist. m | min obstacle dist. m | "
          "path vs ideal | arrival vs ideal | fallbacks | pz_buffer m | acceleration m/s² | "
          "altitude margin m | wall s |\n|" + "---|" * 17)


def _f(x: float | None, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def record(cond: str, name: str, s: dict[str, Any], ideal: dict[str, Any] | None,
           wall: float) -> dict[str, Any]:
    """A run's row: its summary's figures, its costs against the ideal run of the scenario
    (None when that has not finished) and the margins the simulator derived."""
    def ratio(key: str) -> float | None:
        return s[key] / ideal[key] if ideal and s[key] and ideal[key] else None

    m = s["margins"]
    return {"kind": "run", "condition": cond, "scenario": name, "reached": s["reached"],
            "agents": s["agents"], **{k: s[k] for k in EVENTS},
            "starts_inside_pz": s["starts_inside_pz"],
            "min_vehicle_distance": s["min_vehicle_distance"],
            "min_obstacle_distance": s["min_obstacle_distance"],
            "path_vs_ideal": ratio("path_length_ratio"),
            "arrival_vs_ideal": ratio("arrival_time_max"), "fallbacks": s["fallbacks"],
            "pz_buffer": m.get("pz_buffer"), "acceleration": m.get("acceleration"),
            "altitude_margin": m.get("altitude_margin"), "wall": wall}


def row(r: dict[str, Any]) -> str:
    accel = "–" if r["acceleration"] is None else f"{r['acceleration']:.3g}"
    return (f"| {r['condition']} | {r['scenario']} | {r['reached']}/{r['agents']} | "
            f"{r['collisions']} | {r['pz_intrusions']} | {r['obstacle_pz_intrusions']} | "
            f"{r['altitude_violations']} | {r['speed_violations']} | "
            f"{_f(r['min_vehicle_distance'])} | {_f(r['min_obstacle_distance'])} | "
            f"{_f(r['path_vs_ideal'], 3)} | {_f(r['arrival_vs_ideal'], 3)} | {r['fallbacks']} | "
            f"{_f(r['pz_buffer'])} | {accel} | {_f(r['altitude_margin'])} | {r['wall']:.1f} |")


def by_condition(runs: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per condition name (in the order of the runs): its runs summed, the smallest
    distances and the median costs."""
    out = {}
    for cond in dict.fromkeys(r["condition"] for r in runs):
        rs = [r for r in runs if r["condition"] == cond]

        def least(key: str, rs: list[dict[str, Any]] = rs) -> float | None:
            vals = [r[key] for r in rs if r[key] is not None]
            return min(vals) if vals else None

        def median(key: str, rs: list[dict[str, Any]] = rs) -> float | None:
            vals = [r[key] for r in rs if r[key] is not None]
            return float(np.median(vals)) if vals else None

        out[cond] = {"scenarios": len(rs), "reached": sum(r["reached"] for r in rs),
                     "agents": sum(r["agents"] for r in rs),
                     **{k: sum(r[k] for r in rs) for k in EVENTS},
                     "starts_inside_pz": sum(r.get("starts_inside_pz", 0) for r in rs),
                     "min_vehicle_distance": least("min_vehicle_distance"),
                     "min_obstacle_distance": least("min_obstacle_distance"),
                     "path": median("path_vs_ideal"), "arrival": median("arrival_vs_ideal")}
    return out


def summary_table(conds: dict[str, dict[str, Any]]) -> list[str]:
    lines = ["| condition | scenarios | arrived | collisions | pz intrusions | altitude violations "
             "| speed violations | min vehicle dist. m | min obstacle dist. m | "
             "path vs ideal (median) | arrival vs ideal (median) |", "|" + "---|" * 11]
    for cond, c in conds.items():
        lines.append(f"| {cond} | {c['scenarios']} | {c['reached']}/{c['agents']} | "
                     f"{c['collisions']} | {c['pz_intrusions']} | {c['altitude_violations']} | "
                     f"{c['speed_violations']} | {_f(c['min_vehicle_distance'])} | "
                     f"{_f(c['min_obstacle_distance'])} | {_f(c['path'], 3)} | "
                     f"{_f(c['arrival'], 3)} |")
    return lines


def _events(c: dict[str, Any]) -> str:
    starts = c.get("starts_inside_pz", 0)  # a pair that starts inside a zone counts as one
    inside = f" ({starts} of them pairs that start inside a zone)" if starts else ""
    note = {"pz_intrusions": inside}
    said = [f"{c[k]} {EVENT_NAMES[k]}{'s' if c[k] > 1 else ''}{note.get(k, '')}"
            for k in EVENTS if c[k]]
    if c["reached"] < c["agents"]:
        said.append(f"{c['agents'] - c['reached']} of {c['agents']} vehicles short of their goal")
    return ", ".join(said) or "none"


def findings(conds: dict[str, dict[str, Any]]) -> list[str]:
    """The summary's sentences: which conditions keep every vehicle safe and home, what the
    margins buy, what the conditions cost (violations count samples, intrusions and collisions
    vehicle pairs or vehicle-obstacle pairs)."""
    real = {k: c for k, c in conds.items() if k != IDEAL and not k.endswith(MARGINS_OFF)}
    clean = [k for k, c in real.items() if _events(c) == "none"]
    out = []
    if clean:
        out.append("- 0 collisions, 0 protected-zone or obstacle-prism intrusions, 0 altitude or "
                   "speed violations, every vehicle home: " + "; ".join(clean) + ".")
    out += [f"- {k}: {_events(c)}." for k, c in real.items() if k not in clean]
    for k, c in conds.items():
        base = conds.get(k.removesuffix(MARGINS_OFF)) if k.endswith(MARGINS_OFF) else None
        if base is None:
            continue
        if _events(c) == _events(base) == "none":
            out.append(f"- {k}: no event either.")
        else:
            out.append(f"- {k}: {_events(c)}; with the derived margins: {_events(base)}. That is "
                       "what the margins buy.")
    path = [c["path"] for c in real.values() if c["path"] is not None]
    arrival = [c["arrival"] for c in real.values() if c["arrival"] is not None]
    if path and arrival:
        out.append(f"- The cost: the median path length against the ideal run is "
                   f"{min(path):.3f}–{max(path):.3f} over these conditions; the median latest "
                   f"arrival {min(arrival):.2f}–{max(arrival):.2f} times the ideal one.")
    return out


def paper_table(runs: list[dict[str, Any]]) -> list[str]:
    """The paper's cases flown by RotorPy's vehicles, beside the paper's distances."""
    def beside(ours: float | None, paper: str) -> str:
        return _f(ours) + ("" if paper == "–" else f" ({paper})")

    lines = ["| case | vehicle | min vehicle dist. m (paper) | min obstacle dist. m (paper) | "
             "pz intrusions | collisions | altitude violations | speed violations | arrived |",
             "|---|---|---|---|---:|---:|---:|---:|---|"]
    for r in runs:
        vehicle = ROTORPY_VEHICLES.get(r["condition"])
        if vehicle is None or r["scenario"] not in PAPER_LABELS:
            continue
        pv, po = PAPER[r["scenario"]]
        lines.append(f"| {PAPER_LABELS[r['scenario']]} | {vehicle} | "
                     f"{beside(r['min_vehicle_distance'], pv)} | "
                     f"{beside(r['min_obstacle_distance'], po)} | {r['pz_intrusions']} | "
                     f"{r['collisions']} | {r['altitude_violations']} | "
                     f"{r['speed_violations']} | {r['reached']}/{r['agents']} |")
    return lines if len(lines) > 2 else []


def cost_note(r: dict[str, Any], batched: bool) -> str:
    """What RotorPy one by one would have cost on a scenario it does not fly (``batched``: the
    batched model flies it)."""
    return (f"`{r['scenario']}` under RotorPy one by one: not run. One {r['dt']:g} s period of its "
            f"{r['agents']} hummingbirds in steady flight costs {r['period_s']:.1f} s of RotorPy "
            f"alone here (each vehicle integrated on its own), so its up to {r['n_steps']} "
            f"periods would take up to {r['period_s'] * r['n_steps'] / 3600:.1f} h."
            + (" It flies batched instead (the last rows)." if batched else ""))


def page(rows: list[dict[str, Any]], *, swarm: bool, machine: str, command: str,
         partial: bool = False) -> str:
    """The whole page from the rows (``kind``: ``run`` or ``rotorpy_cost``)."""
    runs = [r for r in rows if r["kind"] == "run"]
    batched = {r["scenario"] for r in runs if "batched" in r["condition"]}
    notes = [cost_note(r, r["scenario"] in batched) for r in rows if r["kind"] == "rotorpy_cost"]
    skipped = ", ".join(f"`{r['scenario']}`" for r in rows if r["kind"] == "rotorpy_cost")
    title = "# Real-world conditions" + (", the swarm preset" if swarm else "")
    how = ("every run with the `swarm` preset merged into its `selector_options`; the defaults' "
           "run is [real-world.md](real-world.md)." if swarm else "the simulator's defaults.")
    conds = by_condition(runs)
    lines = [title, "", machine, "", f"`{command}`: {how}", "", "## Summary by condition", "",
             "Summed over each condition's scenarios"
             + (f"; RotorPy's hummingbird one by one flies every scenario but {skipped} (too "
                "many vehicles to integrate one at a time)" if skipped else "")
             + ". Cost columns: median over the scenarios against the same scenario flown "
             "ideally.", "",
             *summary_table(conds), "", *findings(conds), ""]
    paper = paper_table(runs)
    if paper:
        lines += ["## The paper's cases under RotorPy", "",
                  "`plane_qp` with the derived margins and the simulator's set-point ramp and "
                  "rate limit; the flight test also with the crazyflie, the vehicle the paper "
                  "flew.", "", *paper, ""]
    lines += ["## Per scenario", "", COSTS, "", HEADER, *map(row, runs), "", *notes]
    if partial:
        lines += ["", "(partial: still running)"]
    return "\n".join(lines)
