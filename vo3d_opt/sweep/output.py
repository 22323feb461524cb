"""What a sweep writes with ``--out DIR``:

* ``encounters.parquet``: one row per encounter (family, seed, index, ``param_*``, the run
  summary with ``selector_options`` as JSON text, ``min_normalised_distance``, ``error``,
  ``run_time``, ``worker``);
* ``summary.json``: the sweep's summary (:func:`vo3d_opt.sweep.stats.aggregate`);
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
from vo3d_opt.report import atomic
from vo3d_opt.sweep.flight import without_avoidance
from vo3d_opt.sweep.runner import SweepResult

with needs("sweep", "vo3d sweep"):
    import pandas as pd
    import yaml

_DPI = 110
#: libyaml's emitter where PyYAML has it: the same text as the pure-Python one, about four
#: times faster (a sweep without avoidance writes tens of thousands of failures).
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


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
    if result.method.name == "none":
        return without_avoidance(data)
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
    elif result.method.name == "none":
        lines.append(
            "Flown without avoidance (every agent avoids: false): "
            "vo3d run THIS_FILE --json replays it."
        )
    else:
        lines.append("Replay: vo3d run THIS_FILE --json (the same summary but timing).")
    return "".join(f"# {line}\n" for line in lines)


def write_failures(result: SweepResult, out: Path) -> list[Path]:
    """``out/failures/<name>.yaml`` for each encounter of :func:`failed_rows` (and no other
    file there: a sweep's failures are exactly its own)."""
    written = []
    folder = out / "failures"
    for _, row in failed_rows(result.rows).iterrows():
        data = failure_scenario(result, int(row["index"]))
        path = folder / f"{data['name']}.yaml"
        text = yaml.dump(data, Dumper=_DUMPER, sort_keys=False, default_flow_style=None, width=100)
        with atomic(path) as tmp:
            tmp.write_text(_header(result, row) + text)
        written.append(path)
    if folder.is_dir():
        for stale in set(folder.glob("*.yaml")) - set(written):
            stale.unlink()
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
    fig.savefig(path, format="png")
    return path


def write_results(result: SweepResult, out: str | Path) -> list[Path]:
    """encounters.parquet, min_distance.png, failures/*.yaml and, last, summary.json in
    ``out``, each written whole under a temporary name and renamed (so the directory holds a
    ``summary.json`` only once everything else is complete); then the sweep's parts, if it
    kept them there, are removed."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    parquet = out / "encounters.parquet"
    with atomic(parquet) as tmp:
        result.rows.to_parquet(tmp, engine="pyarrow", index=False)
    figure = out / "min_distance.png"
    with atomic(figure) as tmp:
        plot_min_distance(result.rows, tmp)
    written = [parquet, figure, *write_failures(result, out)]
    summary = out / "summary.json"
    with atomic(summary) as tmp:
        tmp.write_text(json.dumps(result.summary, indent=2, allow_nan=False) + "\n")
    if result.store is not None and Path(result.store.out).resolve() == out.resolve():
        result.store.finish()
    return [*written, summary]


#: Okabe–Ito colours (distinct under the common colour-vision deficiencies), with line styles
#: so that the curves also differ in grey.
_STYLES = {
    "vo3d": ("#0072B2", "-"),
    "rvo2": ("#E69F00", "--"),
    "none": ("#000000", ":"),
}
_LABELS = {"vo3d": "vo3d (ours)", "rvo2": "RVO2-3D", "none": "no avoidance"}


def plot_closest_approach(family: str, runs: dict[str, pd.DataFrame], path: Path) -> Path:
    """One family's closest approach per encounter, d / max(r_pz_i, r_pz_j), per method
    (``runs``: the rows of each method's sweep of the same encounters): its distribution
    (ECDF) and, on a log scale, the share of encounters closer than each multiple of r_pz
    (the tail, where intrusions and collisions are)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 4.2), dpi=_DPI)
    FigureCanvasAgg(fig)
    ax_cdf, ax_tail = fig.subplots(1, 2)
    for method, rows in runs.items():
        ok = rows[rows["error"].isna()] if "error" in rows else rows
        d = np.sort(ok["min_normalised_distance"].dropna().to_numpy(dtype=float))
        if not d.size:
            continue
        colour, style = _STYLES.get(method, ("#009E73", "-."))
        label = f"{_LABELS.get(method, method)} (n={d.size:,})"
        share = np.arange(1, d.size + 1) / d.size
        ax_cdf.step(d, share, where="post", color=colour, ls=style, lw=1.6, label=label)
        below = d[d <= 1.5]
        if below.size:
            ax_tail.step(
                below,
                share[: below.size],
                where="post",
                color=colour,
                ls=style,
                lw=1.6,
                label=label,
            )
    for ax in (ax_cdf, ax_tail):
        ax.axvline(1.0, color="#D55E00", ls="-.", lw=1.0, label="d = r_pz (intrusion below)")
        ax.set_xlabel("closest approach d / max(r_pz_i, r_pz_j)")
        ax.grid(alpha=0.3)
    ax_cdf.set_ylabel("share of encounters closer (ECDF)")
    ax_cdf.set_xlim(left=0.0)
    ax_tail.set_yscale("log")
    ax_tail.set_xlim(0.0, 1.5)
    ax_tail.set_ylabel("share of encounters closer (log)")
    ax_tail.set_title("the tail: d <= 1.5 r_pz", fontsize=9)
    ax_cdf.legend(fontsize=8, loc="upper left")
    fig.suptitle(f"'{family}': closest approach per encounter, in protected-zone radii")
    fig.tight_layout()
    with atomic(path) as tmp:
        fig.savefig(tmp, format="png")
    return path
