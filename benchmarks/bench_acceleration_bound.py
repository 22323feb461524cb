"""How fast the simulator may change a RotorPy quadrotor's command: the rate limit against the
altitude it loses control of (``vo3d_opt/sim/safety.py``, ``COMMAND_SHARE``).

One hummingbird, 0.2 s control periods, flies random horizontal commands (6 legs per run, each a
random heading at a random speed up to 4 m/s held for 3-14 periods; seeds 0 to K-1 of ``--seeds
K``, default 8), its commands rate-limited to ``|u_k - u_k-1| <= a dt`` per axis as the
simulator does (``safety.within_reach``). No command asks for any vertical speed, so every metre
of altitude gained or lost is the controller's coupling. For each rate ``a`` (and the share it
corresponds to, ``a = share g / (k_v dt)``) and each way of handing a command to the vehicle
(the set-point ramped over the period, the default, or stepped at its start,
``dynamics.command_ramp``): the largest altitude excursion over the run, per seed, the largest
vertical speed, and the largest speed over the largest command.

    python benchmarks/bench_acceleration_bound.py [--seeds 8]
        [--out docs/results/acceleration-bound.md]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
from pages import RESULTS, machine_line, write_page

from vo3d_opt.sim.dynamics import RotorPyDynamics, vehicle_params
from vo3d_opt.sim.safety import COMMAND_SHARE, GAP_SHARE, G, within_reach

DT, V_MAX, Z0 = 0.2, 4.0, 10.0
SHARES = (0.5, 0.4, 0.3, 0.25, 0.2)


def legs(seed: int, n: int = 6) -> list[np.ndarray]:
    """The commands of one run: n legs of random heading and speed, 3-14 periods each."""
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []
    for _ in range(n):
        heading, speed = rng.uniform(0, 2 * np.pi), rng.uniform(0, V_MAX)
        u = np.array([[speed * np.cos(heading), speed * np.sin(heading), 0.0]])
        out += [u] * int(rng.integers(3, 15))
    return out


def excursion(accel: float, seed: int, ramp: bool) -> tuple[float, float, float]:
    """(largest |z - z0|, largest |v_z|, largest speed - largest command) of one run under
    bound ``accel``."""
    dyn = RotorPyDynamics("hummingbird", command_ramp=ramp)
    dyn.reset(np.array([[0.0, 0.0, Z0]]), np.zeros((1, 3)))
    u, dz, vz, speed, asked = np.zeros((1, 3)), 0.0, 0.0, 0.0, 0.0
    for target in legs(seed):
        u = within_reach(target, u, accel, DT, np.array([V_MAX]))
        r = dyn.step(u, DT)
        dz = max(dz, float(np.abs(r.sample_positions[:, 0, 2] - Z0).max()))
        vz = max(vz, float(np.abs(r.sample_velocities[:, 0, 2]).max()))
        speed = max(speed, float(np.linalg.norm(r.sample_velocities[:, 0], axis=1).max()))
        asked = max(asked, float(np.linalg.norm(u)))
    return dz, vz, speed - asked


def measure(seeds: int) -> list[dict[str, Any]]:
    """One row per (set-point, share): the altitude excursion of each seed, the worst vertical
    speed and the worst speed over the command."""
    k_v = float(vehicle_params("hummingbird").get("k_v", 10.0))
    rows = []
    for ramp in (True, False):
        for share in SHARES:
            accel = share * G / (k_v * DT)
            runs = [excursion(accel, seed, ramp) for seed in range(seeds)]
            rows.append({"ramp": ramp, "share": share, "accel": accel, "dz": [r[0] for r in runs],
                         "vz": max(r[1] for r in runs), "over": max(r[2] for r in runs)})
            print(f"{rows[-1]}", file=sys.stderr, flush=True)
    return rows


def finding(rows: list[dict[str, Any]]) -> str:
    """What the rows say at the project's share: the worst excursion ramped and stepped."""
    worst = {r["ramp"]: max(r["dz"]) for r in rows if r["share"] == COMMAND_SHARE}
    if len(worst) < 2:
        return ""
    return (f"At the project's share ({COMMAND_SHARE}) the worst altitude excursion is "
            f"{worst[True]:.2f} m with the set-point ramped and {worst[False]:.2f} m with it "
            "stepped.")


def page(seeds: int, rows: list[dict[str, Any]], machine: str) -> str:
    """The whole page from ``measure``'s rows, under the ``machine`` line that measured them."""
    k_v = float(vehicle_params("hummingbird").get("k_v", 10.0))
    which = "seed 0" if seeds == 1 else f"seeds 0-{seeds - 1}"
    lines = [
        "# The command rate under RotorPy: altitude lost to horizontal manoeuvres", "",
        machine, "",
        f"`python benchmarks/bench_acceleration_bound.py --seeds {seeds}`: one hummingbird "
        f"(k_v {k_v:g}), {DT} s control periods, random horizontal commands ({which}; the "
        "script's docstring says how they are drawn) rate-limited to `|u_k - u_k-1| <= a dt` "
        "per axis as the simulator does. No command asks for a vertical speed, so every metre of "
        "altitude gained or lost is the controller's coupling. The project rate-limits commands "
        f"at COMMAND_SHARE {COMMAND_SHARE} of g / k_v per period; the selector plans with "
        f"GAP_SHARE {GAP_SHARE}. \"ramped\": the set-point ramped over the period (the default), "
        "\"stepped\": stepped at its start (`dynamics.command_ramp`).", "",
        "| set-point | share of g / k_v | rate a m/s² | altitude excursion per seed m | worst m "
        "| worst vz m/s | worst speed over the command m/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {'ramped' if r['ramp'] else 'stepped'} | {r['share']} | "
                     f"{r['accel']:.2f} | {', '.join(f'{x:.2f}' for x in r['dz'])} | "
                     f"{max(r['dz']):.2f} | {r['vz']:.2f} | {r['over']:.2f} |")
    return "\n".join([*lines, "", finding(rows)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8, help="runs per row (seeds 0..K-1)")
    ap.add_argument("--out", type=Path, default=RESULTS / "acceleration-bound.md")
    args = ap.parse_args()
    if args.seeds < 1:
        ap.error("--seeds must be at least 1")
    write_page(args.out, page(args.seeds, measure(args.seeds), machine_line()))
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
