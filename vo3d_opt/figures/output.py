"""Figures written to files: one ``plot_*`` per ``figure_*``, and :func:`write_plots` for all."""

from __future__ import annotations

from pathlib import Path

from vo3d_opt.extras import needs
from vo3d_opt.sim.metrics import closest_obstacle_approach
from vo3d_opt.sim.record import RunRecord

from .distances import figure_obstacle_distance, figure_vehicle_distance
from .scene import DEFAULT_ZONES, Zones, zone_snapshots
from .style import DEFAULT_DPI, FORMATS, LEGEND_MAX_AGENTS, check_dpi, save_figure
from .swarm import figure_swarm_top_view
from .topview import figure_agents_top_view
from .view3d import figure_trajectories_3d

with needs("sim", "plotting"):
    from matplotlib.figure import Figure


def _written(fig: Figure | None, path: str | Path, dpi: int) -> Path | None:
    return None if fig is None else save_figure(fig, path, dpi)


def plot_trajectories_3d(
    record: RunRecord, path: str | Path, *, dpi: int = DEFAULT_DPI, zones: Zones = DEFAULT_ZONES
) -> Path:
    """Write :func:`figure_trajectories_3d` to ``path`` (.png, .pdf or .svg)."""
    return save_figure(figure_trajectories_3d(record, zones=zones), path, dpi)


def plot_top_view(
    record: RunRecord, path: str | Path, *, dpi: int = DEFAULT_DPI, zones: Zones = DEFAULT_ZONES
) -> Path:
    """Write :func:`figure_top_view` to ``path`` (.png, .pdf or .svg)."""
    return save_figure(figure_top_view(record, zones=zones), path, dpi)


def plot_vehicle_distance(
    record: RunRecord, path: str | Path, *, dpi: int = DEFAULT_DPI
) -> Path | None:
    """Write :func:`figure_vehicle_distance` to ``path``; None (no file) for one vehicle."""
    return _written(figure_vehicle_distance(record), path, dpi)


def plot_obstacle_distance(
    record: RunRecord, path: str | Path, *, dpi: int = DEFAULT_DPI
) -> Path | None:
    """Write :func:`figure_obstacle_distance` to ``path``; None (no file) without a physical
    obstacle."""
    return _written(figure_obstacle_distance(record), path, dpi)


def skipped_plots(record: RunRecord) -> dict[str, str]:
    """The figures :func:`write_plots` leaves out for this run, and why."""
    out = {}
    if record.n_agents < 2:
        out["vehicle_distance"] = "one vehicle: no vehicle-vehicle distance"
    if closest_obstacle_approach(record) is None:
        out["obstacle_distance"] = "no physical obstacle"
    return out


def figure_top_view(record: RunRecord, *, zones: Zones = DEFAULT_ZONES) -> Figure:
    """Top view (Figs. 13a, 15a, 19a): every path over the named obstacles and their protected
    prisms (:func:`~vo3d_opt.figures.topview.figure_agents_top_view`); beyond
    ``LEGEND_MAX_AGENTS`` vehicles, the swarm's view
    (:func:`~vo3d_opt.figures.swarm.figure_swarm_top_view`)."""
    if record.n_agents > LEGEND_MAX_AGENTS:
        return figure_swarm_top_view(record, zones=zones)
    return figure_agents_top_view(record, zones=zones)


def write_plots(
    record: RunRecord,
    out_dir: str | Path,
    *,
    fmt: str = "png",
    dpi: int = DEFAULT_DPI,
    zones: Zones = DEFAULT_ZONES,
) -> list[Path]:
    """All figures into ``out_dir`` as ``fmt`` (png, pdf, svg): trajectories_3d, top_view and,
    when they have something to show, vehicle_distance (two vehicles or more) and
    obstacle_distance (physical obstacles); :func:`skipped_plots` says which were left out.
    Returns the paths written."""
    if fmt not in FORMATS:
        raise ValueError(f"fmt: {fmt!r} is not one of {', '.join(FORMATS)}")
    check_dpi(dpi)
    zones = zone_snapshots(record, zones)  # once for all figures; bad zones fail here
    out = Path(out_dir)
    written = [
        plot_trajectories_3d(record, out / f"trajectories_3d.{fmt}", dpi=dpi, zones=zones),
        plot_top_view(record, out / f"top_view.{fmt}", dpi=dpi, zones=zones),
        plot_vehicle_distance(record, out / f"vehicle_distance.{fmt}", dpi=dpi),
        plot_obstacle_distance(record, out / f"obstacle_distance.{fmt}", dpi=dpi),
    ]
    return [p for p in written if p is not None]
