"""The cost model: microseconds per ``select()`` against the number of neighbours and of
obstacles, for each preset, as a table and a figure.

For every cell of the grid (neighbours 0-20 by obstacles 0-20) the script draws ``--cases``
random encounters (seeded by the cell, the same for every preset): the deciding vehicle at
50 m altitude flying 3 m/s east towards a goal to the east; neighbours 12-50 m away, flying
up to 3 m/s in random directions, half of them on a course to meet it; obstacles (cylinders
and boxes, 1-4 m wide) 10-60 m away horizontally. Each encounter is decided ``--repeat`` times
in a row and its fastest time kept (the machine's noise only adds); a cell's figure is the
median over its encounters. Every preset decides the same encounters in the same process.

    python benchmarks/bench_cost_model.py [--cases 40] [--repeat 3]
        [--out docs/results/cost-model.md]

Writes the page (machine, date and commit at the top) and its figure beside it (``.png``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from pages import RESULTS, machine_line, write_page

from vo3d_opt import AgentState, Box, Cylinder, Limits, Neighbor, VelocitySelector
from vo3d_opt.config import PRESETS

NEIGHBOURS = (0, 1, 2, 5, 10, 15, 20)
OBSTACLES = (0, 1, 2, 5, 10, 20)
SENSING_RANGE = 55.0


def encounter(n_nb: int, n_obs: int, rng: np.random.Generator) -> dict:
    """One random decision with ``n_nb`` neighbours and ``n_obs`` obstacles (module docstring)."""
    own = np.array([0.0, 0.0, 50.0])
    nbs = []
    for k in range(n_nb):
        d = rng.normal(size=3)
        d[2] *= 0.3
        d /= np.linalg.norm(d)
        p = own + rng.uniform(12.0, 50.0) * d
        if k % 2 == 0:  # on a course to meet the vehicle
            v = (own - p) / np.linalg.norm(own - p) * rng.uniform(1.0, 3.0)
        else:
            v = rng.uniform(-3.0, 3.0, 3)
        nbs.append(Neighbor(position=p, velocity=v, r_pz=5.0))
    obstacles: list[Cylinder | Box] = []
    for k in range(n_obs):
        angle, reach = rng.uniform(0.0, 2 * np.pi), rng.uniform(10.0, 60.0)
        centre = (reach * np.cos(angle), reach * np.sin(angle))
        if k % 2:
            obstacles.append(Cylinder(center=centre, radius=rng.uniform(0.5, 2.0), height=80.0))
        else:
            size = (rng.uniform(1.0, 4.0), rng.uniform(1.0, 4.0))
            obstacles.append(Box(center=centre, size=size, height=80.0, yaw=rng.uniform(0, 3)))
    return dict(
        own=AgentState(position=own, velocity=(3.0, 0.0, 0.0)),
        preferred_velocity=(4.0, 0.0, 0.0),
        neighbors=nbs,
        obstacles=obstacles,
        limits=Limits(speed=(0.0, 5.0), altitude=(0.0, 100.0)),
        dt=0.2,
        sensing_range=SENSING_RANGE,
    )


def cell_us(sel: VelocitySelector, cases: list[dict], repeat: int) -> float:
    """Median over ``cases`` of the fastest of ``repeat`` decisions, µs."""
    best = []
    for kw in cases:
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter_ns()
            sel.select(**kw)
            times.append(time.perf_counter_ns() - t0)
        best.append(min(times) / 1e3)
    return float(np.median(best))


def measure(cases: int, repeat: int) -> dict[str, np.ndarray]:
    """{preset: (len(NEIGHBOURS), len(OBSTACLES)) µs}."""
    selectors = {name: VelocitySelector(preset=name) for name in PRESETS}
    out = {name: np.zeros((len(NEIGHBOURS), len(OBSTACLES))) for name in PRESETS}
    for i, n_nb in enumerate(NEIGHBOURS):
        for j, n_obs in enumerate(OBSTACLES):
            rng = np.random.default_rng([n_nb, n_obs])
            drawn = [encounter(n_nb, n_obs, rng) for _ in range(cases)]
            for name, sel in selectors.items():
                sel.select(**drawn[0])  # the first call of a cell is not timed
                out[name][i, j] = cell_us(sel, drawn, repeat)
    return out


def figure(table: dict[str, np.ndarray], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(table), figsize=(3.2 * len(table), 3.2), sharey=True)
    for ax, (name, us) in zip(np.atleast_1d(axes), table.items(), strict=True):
        for j, n_obs in enumerate(OBSTACLES):
            ax.plot(NEIGHBOURS, us[:, j], marker="o", ms=3, label=f"{n_obs} obstacles")
        ax.set_title(f"preset {name}")
        ax.set_xlabel("neighbours")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("µs per select() (median)")
    np.atleast_1d(axes)[-1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=150)


def page(table: dict[str, np.ndarray], cases: int, repeat: int, png: Path) -> str:
    lines = [
        "# Cost model: µs per decision against neighbours and obstacles",
        "",
        machine_line(),
        "",
        f"`python benchmarks/bench_cost_model.py --cases {cases} --repeat {repeat}`: one "
        "`select()` through the public API, `plane_qp` on its default solver, for each preset; "
        f"each cell the median over {cases} random encounters of the fastest of {repeat} calls "
        "(the script's docstring says how they are drawn). Sensing range "
        f"{SENSING_RANGE:g} m.",
        "",
        f"![µs per decision]({png.name})",
        "",
    ]
    for name, us in table.items():
        lines += [f"## Preset `{name}`", "",
                  "| neighbours \\ obstacles | " + " | ".join(map(str, OBSTACLES)) + " |",
                  "|---:|" + "---:|" * len(OBSTACLES)]
        for i, n_nb in enumerate(NEIGHBOURS):
            lines.append(f"| {n_nb} | " + " | ".join(f"{x:.1f}" for x in us[i]) + " |")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=RESULTS / "cost-model.md")
    args = ap.parse_args(argv)
    table = measure(args.cases, args.repeat)
    png = args.out.with_suffix(".png")
    figure(table, png)
    write_page(args.out, page(table, args.cases, args.repeat, png))
    print(f"wrote {args.out} and {png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
