"""What a sweep writes with ``--out DIR``:

* ``encounters.parquet``: one row per encounter (family, seed, index, ``param_*``, the §3
  summary with ``selector_options`` as JSON text, ``min_normalised_distance``, ``error``,
  ``run_time``, ``worker``);
* ``summary.json``: the sweep's summary (contract §6 keys and more);
* ``min_distance.png``: the distribution of each encounter's smallest vehicle-vehicle distance
  over the larger protected-zone radius of the pair (d / r_pz; below 1 is an intrusion), as an
  ECDF and a histogram, per family and method;
* ``failures/<name>.yaml``: every encounter that collided or intruded (vehicle or obstacle
  protected zone), left an agent short of its goal or broke a limit, as a scenario file that
  ``vo3d run`` replays to the same summary (with ``--method vo3d``; for ``rvo2`` the file is
  the encounter, which ``vo3d run`` flies with vo3d and ``vo3d_opt.baselines.run_rvo2`` with
  RVO2-3D).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.generators import make_encounter
from vo3d_opt.sweep.runner import SweepResult

with needs("sweep", "vo3d sweep"):
    import pandas as pd
    import yaml

_DPI = 110


def failed_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """The encounters that ran and collided, intruded (vehicle or obstacle protected zone),
    left an agent short of its goal or broke an altitude or speed limit."""
    if "collisions" not in rows:
        return rows.iloc[:0]

    def col(name: str) -> pd.Series:
        return rows[name].fillna(0)

    bad = (
        (col("collisions") > 0)
        | (col("pz_intrusions") > 0)
        | (col("obstacle_pz_intrusions") > 0)
        | (col("reached") < col("agents"))
        | (col("altitude_violations") + col("speed_violations") > 0)
    )
    return rows[bad & rows["error"].isna()]


def failure_scenario(result: SweepResult, index: int) -> dict[str, Any]:
    """The scenario dict of encounter ``index``, regenerated, with the sweep's formulation,
    solver and selector options (when it named them) so that ``vo3d run`` flies it the same
    way."""
    data = dict(make_encounter(result.family, result.seed, index).scenario)
    if result.method.name == "vo3d":
        for key in ("formulation", "solver"):
            value = getattr(result.method, key)
            if value is not None:
                data[key] = value
        if result.method.selector_options:
            data["selector_options"] = {
                **data.get("selector_options", {}),
                **dict(result.method.selector_options),
            }
    return data


def _header(result: SweepResult, row: pd.Series) -> str:
    lines = [
        f"Encounter {row['index']} of the '{result.family.name}' sweep (seed {result.seed}, "
        f"method {result.method.name}): collisions {int(row['collisions'])}, "
        f"pz_intrusions {int(row['pz_intrusions'])}, obstacle_pz_intrusions "
        f"{int(row['obstacle_pz_intrusions'])}, reached {int(row['reached'])} of "
        f"{int(row['agents'])}, altitude_violations {int(row['altitude_violations'])}, "
        f"speed_violations {int(row['speed_violations'])}."
    ]
    if result.method.name == "rvo2":
        lines.append(
            "Flown by RVO2-3D in the sweep: replay with vo3d_opt.baselines.run_rvo2; "
            "`vo3d run` flies it with vo3d instead."
        )
    else:
        lines.append("Replay: vo3d run THIS_FILE --json (the same summary but timing).")
    return "".join(f"# {line}\n" for line in lines)


def write_failures(result: SweepResult, out: Path) -> list[Path]:
    """``out/failures/<name>.yaml`` for each encounter of :func:`failed_rows`."""
    written = []
    for _, row in failed_rows(result.rows).iterrows():
        data = failure_scenario(result, int(row["index"]))
        path = out / "failures" / f"{data['name']}.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
        path.write_text(_header(result, row) + text)
        written.append(path)
    return written


def plot_min_distance(rows: pd.DataFrame, path: Path) -> Path:
    """ECDF and histogram of ``min_normalised_distance`` per (family, method) against r_pz."""
    with needs("sweep", "sweep figures"):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 4.2), dpi=_DPI)
    FigureCanvasAgg(fig)
    ax_cdf, ax_hist = fig.subplots(1, 2)
    ok = rows[rows["error"].isna()] if "min_normalised_distance" in rows else rows.iloc[:0]
    groups = ok.groupby(["family", "method"]) if len(ok) else []
    for (family, method), g in groups:
        d = np.sort(g["min_normalised_distance"].dropna().to_numpy(dtype=float))
        if not d.size:
            continue
        label = f"{family} ({method}, n={d.size})"
        ax_cdf.step(d, np.arange(1, d.size + 1) / d.size, where="post", label=label)
        ax_hist.hist(d, bins=min(50, max(10, d.size // 20)), histtype="step", label=label)
    for ax in (ax_cdf, ax_hist):
        ax.axvline(1.0, color="tab:red", ls="--", lw=1.0, label="d = r_pz")
        ax.set_xlabel("closest approach d / max(r_pz_i, r_pz_j)")
        ax.grid(alpha=0.3)
    ax_cdf.set_ylabel("fraction of encounters (ECDF)")
    ax_hist.set_ylabel("encounters")
    ax_cdf.legend(fontsize=8)
    fig.suptitle("Smallest vehicle-vehicle distance per encounter, over the protected-zone radius")
    fig.tight_layout()
    fig.savefig(path)
    return path


def write_results(result: SweepResult, out: str | Path) -> list[Path]:
    """encounters.parquet, summary.json, min_distance.png and failures/*.yaml in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    parquet = out / "encounters.parquet"
    result.rows.to_parquet(parquet, engine="pyarrow", index=False)
    summary = out / "summary.json"
    summary.write_text(json.dumps(result.summary, indent=2, allow_nan=False) + "\n")
    written = [parquet, summary, plot_min_distance(result.rows, out / "min_distance.png")]
    return written + write_failures(result, out)
