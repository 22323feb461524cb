"""What a selector can rely on under each vehicle model (formulations/dynamics.md), and what the
models cost.

For every model (kinematic, first_order with tau 0.5 and 1 s, RotorPy's hummingbird at 4 m/s and
crazyflie at 1 m/s) and, for RotorPy, every sub-step rate, one vehicle flies these step commands
through ``vo3d_opt.sim.dynamics`` with 0.2 s control periods, and the sub-step samples give:

* hover -> s:      from rest, command (s, 0, 0);
* right angle:     settled at (s, 0, 0) for 4 s, then (0, s, 0);
* reversal:        settled at (s, 0, 0) for 4 s, then (-s, 0, 0);
* climb:           from rest, command (0, 0, s).

Figures after the step (4 s of flight): the largest speed minus s (overshoot), the largest
vertical speed of a horizontal manoeuvre (or the largest climb rate minus s), the steady error
|v_end - command|, the 5 % settling time (last time |v - v_end| > 0.05 s), the velocity change
reached in one period, the position lag behind the ideal (kinematic) path after one period,
the cross-track excursion (largest distance off the commanded line) and the altitude excursion.
A sub-step rate is compared with a 1 kHz integration through the largest velocity difference at
the period ends of the right-angle manoeuvre. Cost: the time of ``step`` per vehicle per 0.2 s
period (median over the periods; 5 vehicles at once for RotorPy) as CPU time of this process
(``time.process_time``; on a shared machine wall time counts the others' load too). Wind:
hovering in a constant 3 m/s wind, crossing it at s, 20 s of hover in Dryden gusts around 3 m/s
(sigma 1 and 25), and the standard deviation of the gusts themselves.
Sensing: ``Sensor.sensed(i)`` for N = 1000. Batched RotorPy vehicles (``batched: true``, the
``batched`` extra): their cost against one ``Multirotor`` per vehicle, and their accuracy.

    python benchmarks/bench_dynamics.py [--quick] [--sections steps,cost,wind,sensing,batched]
        [--out docs/results/dynamics.md]
"""
from __future__ import annotations

import argparse
import importlib.metadata
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pages import RESULTS, command_line, machine_line, write_page

from vo3d_opt.sim.dynamics import (
    BATCHED_SUBSTEP_RATE,
    DEFAULT_SUBSTEP_RATE,
    Dynamics,
    WindConfig,
    make_dynamics,
    make_wind,
)
from vo3d_opt.sim.sensing import Sensor

DT = 0.2
SETTLE = 4.0   # s of flight before a step from cruise
AFTER = 4.0    # s of flight after the step
REFERENCE_RATE = 1000.0
SECTIONS = ("steps", "cost", "wind", "sensing", "batched")


@dataclass
class Flight:
    """Samples of one vehicle: times (K,), positions and velocities (K, 3), starting at t = 0."""

    t: np.ndarray
    p: np.ndarray
    v: np.ndarray
    t_step: float
    command: np.ndarray
    step_cost: list[float]


def fly(make: Callable[[], Dynamics], phases: list[tuple[np.ndarray, float]], n: int = 1,
        start_z: float = 20.0) -> Flight:
    """Fly ``n`` vehicles through (command, duration) phases; vehicle 0's samples."""
    dyn = make()
    start = np.column_stack([np.arange(n) * 10.0, np.zeros(n), np.full(n, start_z)])
    dyn.reset(start)
    t, p, v, cost = [0.0], [start[0]], [np.zeros(3)], []
    now = 0.0
    for cmd, duration in phases:
        for _ in range(round(duration / DT)):
            t0 = time.process_time()
            out = dyn.step(np.tile(cmd, (n, 1)), DT)
            cost.append((time.process_time() - t0) / n)
            t.extend(now + out.sample_times)
            p.extend(out.sample_positions[:, 0])
            v.extend(out.sample_velocities[:, 0])
            now += DT
    t_step = sum(d for _, d in phases[:-1])
    return Flight(np.array(t), np.array(p), np.array(v), t_step, phases[-1][0], cost)


def manoeuvres(s: float) -> dict[str, list[tuple[np.ndarray, float]]]:
    x, y, z = np.eye(3) * s
    return {"hover -> s": [(x, AFTER)], "right angle": [(x, SETTLE), (y, AFTER)],
            "reversal": [(x, SETTLE), (-x, AFTER)], "climb": [(z, AFTER)]}


def at(f: Flight, time_s: float) -> int:
    return int(np.argmin(np.abs(f.t - time_s)))


def figures(f: Flight, s: float) -> dict[str, float]:
    after = f.t >= f.t_step - 1e-9
    v, p, t = f.v[after], f.p[after], f.t[after]
    k0, k1 = at(f, f.t_step), at(f, f.t_step + DT)
    cmd = f.command
    vertical = cmd[2] != 0
    v_end = v[-1]
    off = np.abs(np.linalg.norm(v - v_end, axis=1)) > 0.05 * s
    settle = (t[np.flatnonzero(off)[-1]] - f.t_step + (t[1] - t[0])) if off.any() else 0.0
    ideal = f.p[k0] + cmd * DT
    rel = p - f.p[k0]
    unit = cmd / np.linalg.norm(cmd)
    cross = np.linalg.norm(rel - np.outer(rel @ unit, unit), axis=1)
    return {
        "speed overshoot m/s": float(np.linalg.norm(v, axis=1).max() - s),
        "max abs vz (climb: vz - s) m/s":
            float(np.abs(v[:, 2]).max() if not vertical else v[:, 2].max() - s),
        "steady error m/s": float(np.linalg.norm(v_end - cmd)),
        "settling s": float(settle),
        "dv in one period m/s": float(np.linalg.norm(f.v[k1] - f.v[k0])),
        "lag after one period m": float(np.linalg.norm(f.p[k1] - ideal)),
        "cross-track m": float(cross.max()),
        "altitude excursion m": float(np.abs(rel[:, 2]).max()) if not vertical else float("nan"),
    }


def period_ends(f: Flight) -> np.ndarray:
    ends = np.arange(DT, f.t[-1] + 1e-9, DT)
    return np.array([f.v[at(f, e)] for e in ends])


def table(header: list[str], rows: list[list[Any]]) -> str:
    def cell(x: Any) -> str:
        if isinstance(x, float):
            return "–" if np.isnan(x) else f"{x:.3g}"
        return str(x)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(x) for x in r) + " |" for r in rows]
    return "\n".join(lines)


def rotorpy(vehicle: str, rate: float, wind: dict | None = None,
            batched: bool = False) -> Callable[[], Dynamics]:
    spec = {"model": "rotorpy", "vehicle": vehicle, "substep_rate": rate, "batched": batched}
    return lambda: make_dynamics(spec, wind, seed=1)


def step_responses(rates: list[float], out: list[str]) -> None:
    models: list[tuple[str, float, Callable[[], Dynamics]]] = [
        ("kinematic", 4.0, lambda: make_dynamics()),
        ("first_order tau 0.5 s", 4.0, lambda: make_dynamics({"model": "first_order", "tau": 0.5})),
        ("first_order tau 1 s", 4.0, lambda: make_dynamics({"model": "first_order", "tau": 1.0})),
    ]
    for vehicle, s in (("hummingbird", 4.0), ("crazyflie", 1.0)):
        models += [(f"rotorpy {vehicle} {rate:g} Hz", s, rotorpy(vehicle, rate))
                   for rate in [*rates, REFERENCE_RATE]]
    # the flight test's speed (paper-flight-test.yaml)
    models.append(("rotorpy crazyflie 0.3 m/s", 0.3, rotorpy("crazyflie", DEFAULT_SUBSTEP_RATE)))
    rows, costs, stability = [], [], []
    refs: dict[str, np.ndarray] = {}
    for name, s, make in models:
        flights = {m: fly(make, phases) for m, phases in manoeuvres(s).items()}
        for m, f in flights.items():
            fig = figures(f, s)
            rows.append([name, f"{s:g}", m, *fig.values()])
            header = list(fig)
        per_step = [c for f in flights.values() for c in f.step_cost]
        costs.append([name, statistics.median(per_step) * 1e3])
        if name.startswith("rotorpy") and name.endswith("Hz"):
            vehicle = name.split()[1]
            ends = period_ends(flights["right angle"])
            if name.endswith(f" {REFERENCE_RATE:g} Hz"):
                refs[vehicle] = ends
            else:
                stability.append((vehicle, name, ends))
    out.append("## Step responses (one vehicle, 0.2 s periods)\n")
    out.append(table(["model", "s m/s", "manoeuvre", *header], rows))
    out.append("\n## Sub-step rate against a 1 kHz integration (right angle)\n")
    gaps = [(veh, name, float(np.abs(e - refs[veh]).max())) for veh, name, e in stability]
    out.append(table(["model", "largest abs(v - v_1kHz) at period ends, m/s"],
                     [[name, gap] for _, name, gap in gaps]))
    out.append(substep_finding(gaps))
    out.append("\n## Cost of step() per vehicle per 0.2 s period (one vehicle, median)\n")
    out.append(table(["model", "ms"], costs))


def substep_finding(gaps: list[tuple[str, str, float]], within: float = 0.2) -> str:
    """The lowest sub-step rate of each vehicle from which every higher rate stays within
    ``within`` m/s of the 1 kHz integration (the names end in "RATE Hz")."""
    found = []
    for vehicle in dict.fromkeys(v for v, _, _ in gaps):
        rows = [(float(name.split()[-2]), gap) for v, name, gap in gaps if v == vehicle]
        good = [rate for rate, _ in rows if all(g <= within for r, g in rows if r >= rate)]
        found.append(f"{vehicle} {min(good):g} Hz" if good else f"{vehicle}: none")
    return (f"\nThe lowest sub-step rate from which every rate tried stays within {within:g} m/s "
            f"of the 1 kHz integration: {', '.join(found)} (the simulator's default: "
            f"{DEFAULT_SUBSTEP_RATE:g} Hz).")


def rotorpy_cost(rates: list[float], out: list[str], n: int = 5) -> None:
    rows = []
    for vehicle, s in (("hummingbird", 4.0), ("crazyflie", 1.0)):
        for rate in rates:
            f = fly(rotorpy(vehicle, rate), [(np.array([s, 0.0, 0.0]), 2.0)], n=n)
            rows.append([vehicle, f"{rate:g}", statistics.median(f.step_cost) * 1e3])
    out.append(f"\n## RotorPy cost per vehicle per 0.2 s period, {n} vehicles at once (median)\n")
    out.append(table(["vehicle", "sub-steps per s", "ms"], rows))


def wind_figures(out: list[str]) -> None:
    rows = []
    wind = np.array([3.0, 0.0, 0.0])
    for vehicle, s in (("hummingbird", 4.0), ("crazyflie", 1.0)):
        const = {"type": "constant", "velocity": wind.tolist()}
        make = rotorpy(vehicle, DEFAULT_SUBSTEP_RATE, const)
        hover = fly(make, [(np.zeros(3), 6.0)])
        rows.append([vehicle, "constant 3 m/s, hover", float(np.linalg.norm(hover.v[-1])),
                     float(np.linalg.norm(hover.v, axis=1).max()),
                     float(np.abs(hover.p[:, 2] - hover.p[0, 2]).max())])
        cross = fly(make, [(np.array([0.0, s, 0.0]), 6.0)])
        rows.append([vehicle, f"constant 3 m/s, crossing at {s:g} m/s",
                     float(np.linalg.norm(cross.v[-1] - [0, s, 0])),
                     float(np.linalg.norm(cross.v - [0, s, 0], axis=1)[cross.t > 3].max()),
                     float(np.abs(cross.p[:, 2] - cross.p[0, 2]).max())])
        for sigma in (1.0, 25.0):
            dryden = {"type": "dryden", "velocity": wind.tolist(), "sigma": [sigma] * 3}
            gust = fly(rotorpy(vehicle, DEFAULT_SUBSTEP_RATE, dryden), [(np.zeros(3), 20.0)])
            speed = np.linalg.norm(gust.v, axis=1)
            rows.append([vehicle, f"Dryden around 3 m/s, sigma {sigma:g}, hover, 20 s",
                         float(np.sqrt(np.mean(speed ** 2))), float(speed.max()),
                         float(np.abs(gust.p[:, 2] - gust.p[0, 2]).max())])
    out.append(f"\n## Wind ({DEFAULT_SUBSTEP_RATE:g} Hz sub-steps)\n")
    out.append(table(["vehicle", "wind, command", "velocity error at the end (RMS for Dryden) m/s",
                     "largest velocity error m/s", "altitude excursion m"], rows))
    out.append(f"\n### RotorPy's Dryden gusts themselves ({DEFAULT_SUBSTEP_RATE:g} Hz samples, "
               "60 s)\n")
    gust_rows = []
    for sigma in (1.0, 25.0):
        np.random.seed(0)
        wind_model = make_wind(WindConfig(type="dryden", velocity=wind, sigma=[sigma] * 3),
                               1.0 / DEFAULT_SUBSTEP_RATE)
        w = np.array([wind_model.update(0.0, np.zeros(3))
                      for _ in range(round(60 * DEFAULT_SUBSTEP_RATE))])
        gust_rows.append([f"{sigma:g}", *(float(x) for x in w.std(axis=0)),
                          float(np.abs(w - wind).max())])
    out.append(table(["sigma m/s", "std x m/s", "std y m/s", "std z m/s", "largest gust m/s"],
                     gust_rows))


def sensing_cost(out: list[str], n: int = 1000) -> None:
    sensor = Sensor(n, DT, position_noise=0.5, velocity_noise=0.3, latency=0.4, seed=1)
    rng = np.random.default_rng(0)
    p, v = rng.uniform(-100, 100, (n, 3)), rng.uniform(-4, 4, (n, 3))
    t0 = time.process_time()
    for _ in range(20):
        sensor.push(p, v)
    push = (time.process_time() - t0) / 20
    times = []
    for i in range(n):
        t0 = time.process_time()
        sensor.sensed(i)
        times.append(time.process_time() - t0)
    out.append(f"\n## Sensing, N = {n}\n")
    out.append(table(["call", "µs (median)"], [["push", push * 1e6],
                                               ["sensed(i)", statistics.median(times) * 1e6]]))


def batched_cost(sizes: list[int], out: list[str], one_by_one_up_to: int = 50) -> None:
    """``batched: true`` against one ``Multirotor`` per vehicle: CPU time per vehicle and period
    (hummingbirds commanded 4 m/s from hover, torch on one thread), how far the batched RK4
    strays from RotorPy's RK45 at the same sub-step rate (100 Hz, 200 Hz) in the step
    manoeuvres, and what importing RotorPy costs with torch installed."""
    try:
        import torch
    except ImportError as exc:
        out.append(f"\n## Batched RotorPy vehicles: not measured ({exc.name} is not installed; "
                   "pip install 'vo3d-opt[batched]')")
        return
    torch.set_num_threads(1)
    rate = BATCHED_SUBSTEP_RATE
    cruise = [(np.array([4.0, 0.0, 0.0]), 1.0)]
    rows = []
    for n in sizes:
        batched = statistics.median(
            fly(rotorpy("hummingbird", rate, batched=True), cruise, n=n).step_cost) * 1e3
        single = (statistics.median(fly(rotorpy("hummingbird", rate), cruise, n=n).step_cost)
                  * 1e3 if n <= one_by_one_up_to else float("nan"))
        rows.append([n, batched, single, single / batched])
    out.append(f"\n## Batched RotorPy hummingbirds (torch {torch.__version__}, one thread, "
               f"{rate:g} Hz): CPU ms per vehicle per 0.2 s period (median)\n")
    out.append(table(["N", "batched (RK4)", "one by one (RK45)", "one by one / batched"], rows))
    diagonal = [(np.array([4.0, 4.0, 0.0]), AFTER)]
    phases = {**manoeuvres(4.0), "diagonal (4, 4, 0) from hover": diagonal}
    acc = []
    for rate_hz in (100.0, BATCHED_SUBSTEP_RATE):
        for name, phase in phases.items():
            pair = [fly(rotorpy("hummingbird", rate_hz, batched=b), phase) for b in (True, False)]
            acc.append([f"{rate_hz:g}", name, float(np.abs(pair[0].p - pair[1].p).max()),
                        float(np.abs(pair[0].v - pair[1].v).max())])
    out.append("\n### Batched (RK4) against one by one (RK45) at the same sub-step rate, one "
          "hummingbird, every sub-step sample\n")
    out.append(table(["sub-steps per s", "manoeuvre", "largest position difference m",
                     "largest velocity difference m/s"], acc))
    rotorpy_import_cost(out)


def rotorpy_import_cost(out: list[str], runs: int = 3) -> None:
    """Wall time of ``import rotorpy.vehicles.multirotor`` in a fresh process: RotorPy imports
    torch at its top when it is installed, whichever model is used; 'without' blocks it."""
    code = ("import sys, time\nif sys.argv[1] == 'without': sys.modules['torch'] = None\n"
            "t = time.perf_counter()\nimport rotorpy.vehicles.multirotor\n"
            "print(time.perf_counter() - t)")
    rows = []
    for torch_state in ("with", "without"):
        times = [float(subprocess.run([sys.executable, "-c", code, torch_state], check=True,
                                      capture_output=True, text=True).stdout)
                 for _ in range(runs)]
        rows.append([f"{torch_state} torch", " / ".join(f"{t:.2f}" for t in times)])
    out.append(f"\n### Importing RotorPy's vehicles ({runs} fresh processes each, s)\n")
    out.append(table(["", "import rotorpy.vehicles.multirotor"], rows))


INTRO = """`{command}`: what a selector can rely on under each vehicle model
([formulations: dynamics](../formulations/dynamics.md)), and what the models cost. One vehicle
flies step commands through `vo3d_opt.sim.dynamics` with {dt:g} s control periods: from hover to
s, a right angle and a reversal after {settle:g} s of cruise at s, and a climb; the figures cover
the {after:g} s after the step (the script's docstring defines each column). Costs are CPU time
of this process (`time.process_time`), so the other work of a shared machine counts less than in
wall time."""


def page(sections: list[str], rates: list[float], command: str, machine: str) -> str:
    """The whole page: the sections named (``steps``, ``cost``, ``wind``, ``sensing``,
    ``batched``), in that order."""
    runs = {
        "steps": lambda out: step_responses(rates, out),
        "cost": lambda out: rotorpy_cost([50.0, 100.0, 200.0], out),
        "wind": wind_figures,
        "sensing": sensing_cost,
        "batched": lambda out: batched_cost([1, 10, 50, 200, 1000], out),
    }
    intro = INTRO.format(command=command, dt=DT, settle=SETTLE, after=AFTER)
    out = ["# Vehicle models: responses and costs\n", machine + "\n", intro + "\n"]
    for name in sections:
        runs[name](out)
        print(f"{name}: done", file=sys.stderr, flush=True)
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer sub-step rates")
    ap.add_argument("--sections", default="steps,cost,wind,sensing,batched",
                    help="comma-separated subset of steps,cost,wind,sensing,batched")
    ap.add_argument("--out", type=Path, default=RESULTS / "dynamics.md")
    args = ap.parse_args()
    sections = args.sections.split(",")
    unknown = set(sections) - set(SECTIONS)
    if unknown:
        ap.error(f"--sections: unknown {', '.join(sorted(unknown))}")
    rates = [50.0, 100.0] if args.quick else [5.0, 10.0, 20.0, 25.0, 40.0, 50.0, 100.0, 200.0]
    extras = [f"rotorpy {_version('rotorpy')}", f"torch {_version('torch')}"]
    write_page(args.out, page(sections, rates, command_line(), machine_line(*extras)))
    print(f"wrote {args.out}", file=sys.stderr)


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


if __name__ == "__main__":
    main()
