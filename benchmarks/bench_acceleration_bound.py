"""How fast the simulator may change a RotorPy quadrotor's command: the rate limit against the
altitude it loses control of (``vo3d_opt/sim/safety.py``, ``COMMAND_SHARE``).

One hummingbird, 0.2 s control periods, flies random horizontal commands (6 legs per run, each a
random heading at a random speed up to 4 m/s held for 3-14 periods; seeds 0-7), its commands
rate-limited to ``|u_k - u_k-1| <= a dt`` per axis as the simulator does
(``safety.within_reach``). No command asks for any vertical speed, so every metre of altitude
gained or lost is the controller's coupling. For each rate ``a`` (and the share it
corresponds to, ``a = share g / (k_v dt)``) and each way of handing a command to the vehicle
(the set-point ramped over the period, the default, or stepped at its start,
``dynamics.command_ramp``): the largest altitude excursion over the run, per seed, the largest
vertical speed, and the largest speed over the largest command.

    python benchmarks/bench_acceleration_bound.py > docs/results/acceleration-bound.md
"""
from __future__ import annotations

import datetime
import platform

import numpy as np

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


def main() -> None:
    k_v = float(vehicle_params("hummingbird").get("k_v", 10.0))
    print("# The command rate under RotorPy: altitude lost to horizontal manoeuvres\n")
    print(f"{platform.machine()}, CPython {platform.python_version()}, "
          f"{datetime.date.today()}. `benchmarks/bench_acceleration_bound.py` (hummingbird, "
          f"k_v {k_v:g}, dt {DT} s; the project rate-limits commands at COMMAND_SHARE "
          f"{COMMAND_SHARE}, the selector plans with GAP_SHARE {GAP_SHARE}).\n")
    print("| set-point | share of g / k_v | rate a m/s² | altitude excursion per seed m | worst m "
          "| worst vz m/s | worst speed over the command m/s |")
    print("|---|---|---|---|---|---|---|")
    for ramp in (True, False):
        for share in SHARES:
            accel = share * G / (k_v * DT)
            runs = [excursion(accel, seed, ramp) for seed in range(8)]
            dz = [r[0] for r in runs]
            print(f"| {'ramped' if ramp else 'stepped'} | {share} | {accel:.2f} | "
                  f"{', '.join(f'{x:.2f}' for x in dz)} | {max(dz):.2f} | "
                  f"{max(r[1] for r in runs):.2f} | {max(r[2] for r in runs):.2f} |", flush=True)


if __name__ == "__main__":
    main()
