"""The figures of the docs (docs/figures.md), written again from the bundled scenarios.

Flies the paper's cases 1, 2 and 4 and the 1,000-vehicle random crossing with the defaults (as
``vo3d run NAME`` does), writes every figure of each run as ``vo3d run NAME --out DIR`` would
(``vo3d_opt.figures.write_plots``) into ``docs/figures/NAME/``, and one frame of case 2's replay
(``vo3d_opt.animation.write_frame``), the moment u1 passes beside obstacles[3].

    python benchmarks/figures.py [--out docs/figures] [--dpi 110]      # or: make figures
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from vo3d_opt.animation import write_frame
from vo3d_opt.figures import write_plots
from vo3d_opt.sim.scenario import bundled_dir
from vo3d_opt.sim.simulator import run_scenario

#: The runs drawn, by bundled scenario name.
SCENARIOS = (
    "paper-case1-ten-uav-crossing",
    "paper-case2-two-uav-six-obstacles",
    "paper-case4-five-uav-six-square-obstacles",
    "random-crossing-1000",
)
#: The replay frame: scenario and time (s).
FRAME = ("paper-case2-two-uav-six-obstacles", 24.4)
OUT = Path(__file__).resolve().parents[1] / "docs" / "figures"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT, help="folder written (default: docs/figures)")
    ap.add_argument("--dpi", type=int, default=110, help="resolution of the PNGs (default: 110)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    for name in SCENARIOS:
        record = run_scenario(bundled_dir() / f"{name}.yaml", progress=False)
        for path in write_plots(record, args.out / name, dpi=args.dpi):
            print(f"wrote {path}")
        if name == FRAME[0]:
            frame = write_frame(record, args.out / name / "replay_frame.png", time=FRAME[1],
                                dpi=args.dpi)
            print(f"wrote {frame}")


if __name__ == "__main__":
    main()
