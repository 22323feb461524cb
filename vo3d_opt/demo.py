"""``make demo``: the paper's case 1 (ten UAVs crossing, section 5, Figs. 13-14) with the default
formulation; writes the figures, the trajectories and the summary to ``./out/demo/``."""

from __future__ import annotations

import sys
from pathlib import Path

from vo3d_opt.report import write_outputs
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import bundled_dir, load_scenario
from vo3d_opt.sim.simulator import Simulator, scenario_selector

SCENARIO = "paper-case1-ten-uav-crossing.yaml"


def run_demo(out_dir: str | Path = Path("out") / "demo") -> int:
    """Run case 1, write ./out/demo/{summary.json, trajectories.parquet, trajectories.csv, *.png},
    print where."""
    out = Path(out_dir)
    sc = load_scenario(bundled_dir() / SCENARIO)
    sel, formulation, solver = scenario_selector(sc)
    print(f"running {sc.name}: {sc.n_agents} UAVs, {formulation} / {solver} ...", flush=True)
    record = Simulator(sc, sel, formulation=formulation, solver=solver).run()
    summary = summarize(record)
    files = write_outputs(record, summary, out)
    print(
        f"{summary['reached']}/{summary['agents']} arrived in {summary['time']:.1f} s "
        f"simulated; closest approach {summary['min_vehicle_distance']:.3f} m "
        f"(r_pz {float(sc.r_pz.max()):g} m); pz intrusions {summary['pz_intrusions']}, "
        f"collisions {summary['collisions']}; decision time median "
        f"{summary['decision_time_median_us']:.0f} us"
    )
    print(f"wrote {len(files)} files to {out.resolve()}:")
    for f in files:
        print(f"  {f}")
    return 0


if __name__ == "__main__":
    sys.exit(run_demo())
