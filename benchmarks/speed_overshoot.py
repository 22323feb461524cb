"""What the speed margin buys under RotorPy: encounters of the ``rotorpy`` sweep family flown
by our method planning at each vehicle's top speed (``safety.speed_margin: 0``) and with the
margin the simulator derives, side by side.

    python benchmarks/speed_overshoot.py --indices 1 7 14 ... [--seed 0] [--out PAGE]
    python benchmarks/speed_overshoot.py --files DIR_OR_FILES ... [--out PAGE]

Flies every encounter given (``--indices``: of the ``rotorpy`` family with ``--seed``, as the
sweep draws them; ``--files``: scenario files) both ways, all runs in one ``RotorPyFleet`` (the
same numbers as each alone), and writes a page: per encounter its wind, and both ways the
vehicle-steps whose true speed, sampled at every sub-step, is above the top speed (what the
sweep counts as a speed violation), the largest such excess and the largest commanded speed
over the top speed. An excess above :data:`LARGE` is flown again by the one-by-one model, to
tell the vehicle from the integrator.
"""

from __future__ import annotations

import argparse
import threading
from pathlib import Path
from typing import Any

import numpy as np
from pages import RESULTS, machine_line, write_page  # this folder's

from vo3d_opt.generators import make_encounter
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.rotorpy_fleet import RotorPyFleet, import_torch
from vo3d_opt.sim.scenario import Scenario, load_scenario, scenario_from_dict, scenario_variant
from vo3d_opt.sim.simulator import fly, scenario_dynamics
from vo3d_opt.sweep.flight import Method, flown

#: An excess above this (m/s) is not the velocity loop settling.
LARGE = 0.1
WAYS = ("at top speed", "with margin")


def replay(scenarios: list[Scenario]) -> list[Any]:
    """Each scenario's record, flown by our method in one fleet."""
    fleet = RotorPyFleet()
    models = [scenario_dynamics(sc, fleet=fleet) for sc in scenarios]
    records: list[Any] = [None] * len(scenarios)

    def one(k: int) -> None:
        try:
            sc, step, _ = flown(scenarios[k], Method())
            records[k] = fly(sc, step, dynamics=models[k], progress=False)
        finally:
            models[k].leave()

    threads = [threading.Thread(target=one, args=(k,)) for k in range(len(scenarios))]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    except BaseException:  # a Ctrl-C: the runs end at their next period
        fleet.abort()
        raise
    for k, sc in enumerate(scenarios):  # a run the fleet failed flies alone (the same numbers)
        if records[k] is None:
            flown_sc, step, _ = flown(sc, Method())
            records[k] = fly(flown_sc, step, progress=False)
    return records


def excess(record: Any) -> dict[str, Any]:
    """A record's speed violations, largest true and commanded speed over the top speed."""
    v_max = record.scenario.max_speed[None, :]
    true = np.linalg.norm(record.sample_velocities, axis=-1) - v_max
    return {
        "violations": summarize(record)["speed_violations"],
        "largest": float(true.max()),
        "command": float((np.linalg.norm(record.commands, axis=-1) - v_max).max()),
    }


def one_by_one(sc: Scenario) -> float:
    """The largest excess of ``sc`` flown by the one-by-one RotorPy model (RK45, 100 Hz)."""
    data = sc.model_dump(exclude_none=True)
    data["dynamics"] = {**data["dynamics"], "batched": False}
    plain = scenario_from_dict(data, sc.source)
    sc2, step, _ = flown(plain, Method())
    return excess(fly(sc2, step, progress=False))["largest"]


def both_ways(sc: Scenario) -> list[Scenario]:
    """``sc`` planned at the top speed, and as the simulator derives its margins."""
    at_top = scenario_variant(sc, safety={**sc.safety.model_dump(), "speed_margin": 0.0})
    return [at_top, sc]


def row(sc: Scenario, records: list[Any]) -> dict[str, Any]:
    """The page's row of ``sc`` from its two records (at the top speed, with the margin)."""
    wind = sc.wind
    r = {
        "name": sc.name,
        "wind": "none" if wind is None else f"{wind.type} {np.linalg.norm(wind.velocity):.2f} m/s",
        "top speeds": f"{sc.max_speed.min():.2f}–{sc.max_speed.max():.2f}",
        **{w: excess(rec) for w, rec in zip(WAYS, records, strict=True)},
    }
    if max(r[w]["largest"] for w in WAYS) > LARGE:
        r["one by one"] = one_by_one(both_ways(sc)[0])
    return r


def render(rows: list[dict[str, Any]], command: str) -> str:
    total = {w: sum(r[w]["violations"] > 0 for r in rows) for w in WAYS}
    worst = {w: max(r[w]["largest"] for r in rows) for w in WAYS}
    cmd = {w: max(r[w]["command"] for r in rows) for w in WAYS}
    large = [r for r in rows if r[WAYS[0]]["largest"] > LARGE or r[WAYS[1]]["largest"] > LARGE]
    lines = [
        "# RotorPy's speed overshoot, and the speed margin",
        "",
        machine_line(),
        "",
        f"`{command}`: {len(rows)} encounters of the `rotorpy` family (hummingbirds in winds of",
        "up to 3 m/s, constant or Dryden gusts; the group draws cruise at their top speed), flown",
        "by our method planning at each vehicle's top speed (`safety.speed_margin: 0`) and with",
        "the margin the simulator derives (0.1 m/s under RotorPy in wind), each run as in the",
        "sweep. A speed violation is a vehicle-step in which the true speed, sampled at every",
        "RotorPy sub-step, is above the vehicle's top speed; the commands are what the selector",
        "chose.",
        "",
        "| | encounters with a speed violation | largest speed over the top speed m/s "
        "| largest command over the top speed m/s |",
        "|---|---:|---:|---:|",
        *(f"| {w} | {total[w]} of {len(rows)} | {worst[w]:.4f} | {cmd[w]:.3g} |" for w in WAYS),
        "",
        "Planning at the top speed, the commands stay within it and RotorPy's velocity loop",
        "overshoots them in gusts; the margin keeps every sample within the top speed."
        if total[WAYS[1]] == 0
        else "With the margin some vehicle still flies above its top speed (the table below).",
    ]
    for r in large:
        lines.append(
            f"{r['name']}: above {LARGE} m/s; flown by the one-by-one model (RK45, 100 Hz) at "
            f"the top speed {r['one by one']:.3f} m/s."
        )
    lines += [
        "",
        "| encounter | wind | violations at top speed | largest speed over it m/s "
        "| violations with margin | largest speed over it m/s | top speeds m/s |",
        "|---|---|---:|---:|---:|---:|---|",
    ]
    for r in sorted(rows, key=lambda r: -r[WAYS[0]]["largest"]):
        a, b = r[WAYS[0]], r[WAYS[1]]
        lines.append(
            f"| {r['name']} | {r['wind']} | {a['violations']} | {a['largest']:.4f} | "
            f"{b['violations']} | {b['largest']:.4f} | {r['top speeds']} |"
        )
    return "\n".join(lines) + "\n"


def scenarios_given(args: argparse.Namespace) -> list[Scenario]:
    """The encounters of ``--indices`` (as the sweep draws them) or the files of ``--files``."""
    if args.indices:
        return [make_encounter("rotorpy", args.seed, i).load() for i in args.indices]
    paths = sorted(f for x in args.files for f in (sorted(x.glob("*.yaml")) if x.is_dir() else [x]))
    return [load_scenario(f) for f in paths]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    given = p.add_mutually_exclusive_group(required=True)
    given.add_argument("--indices", nargs="+", type=int, help="encounters of the rotorpy family")
    given.add_argument("--files", nargs="+", type=Path, help="scenario files or folders of them")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=RESULTS / "sweeps" / "rotorpy-speed.md")
    args = p.parse_args()
    import_torch().set_num_threads(1)  # as a sweep's worker flies them
    scenarios = scenarios_given(args)
    records = replay([v for sc in scenarios for v in both_ways(sc)])
    rows = [row(sc, records[2 * k : 2 * k + 2]) for k, sc in enumerate(scenarios)]
    shown = (
        ("--indices " + " ".join(map(str, args.indices)))
        if args.indices
        else (
            "--files "
            + " ".join(str(x) for x in args.files).replace(str(RESULTS.parents[1]) + "/", "")
        )
    )
    seed = f" --seed {args.seed}" if args.indices and args.seed else ""
    write_page(args.out, render(rows, f"python benchmarks/speed_overshoot.py {shown}{seed}"))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
