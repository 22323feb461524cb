"""Figures of a run, like the paper's Figs. 13-20: 3D trajectories, the top view with the
obstacles, and the vehicle-vehicle and vehicle-obstacle distances over time.

Figures are drawn on ``matplotlib.figure.Figure`` with the Agg canvas, so importing this module
never changes the global matplotlib backend (notebooks keep theirs). Each function takes a
:class:`~vo3d_opt.sim.simulator.RunRecord` and writes one PNG.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from vo3d_opt.sim.metrics import nearest_obstacle_distance, nearest_vehicle_distance
from vo3d_opt.sim.simulator import RunRecord
from vo3d_opt.types import Box, Cylinder

_DPI = 110


def _colors(n: int) -> list:
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "tab20" if n <= 20 else "turbo"]
    if n <= 20:
        return [cmap(i % cmap.N) for i in range(n)]
    return [cmap(x) for x in np.linspace(0.05, 0.95, n)]


def _new(figsize=(7.0, 5.5)) -> Figure:
    fig = Figure(figsize=figsize, dpi=_DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def _box_corners(box: Box) -> np.ndarray:
    """The box's four footprint corners (4, 2), counter-clockwise."""
    lx, ly = box.size / 2.0
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    local = np.array([[-lx, -ly], [lx, -ly], [lx, ly], [-lx, ly]])
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + box.center


def _legend(ax, n: int) -> None:
    if n <= 12:
        ax.legend(fontsize="small", loc="best", ncol=2 if n > 6 else 1)


def plot_trajectories_3d(record: RunRecord, path: str | Path) -> Path:
    """3D flight paths (start o, goal x) with cylinders, boxes and spheres (Figs. 13b, 15b)."""
    sc = record.scenario
    fig = _new((7.5, 6.5))
    ax = fig.add_subplot(projection="3d")
    colors = _colors(record.n_agents)
    z_top = sc.limits.altitude[1]
    for body, spec in zip(sc.bodies, sc.obstacles):
        h = min(body.height, z_top * 1.1)
        alpha = 0.25 if spec.sensed else 0.12
        if isinstance(body, Cylinder):
            th, zz = np.meshgrid(np.linspace(0, 2 * np.pi, 28), np.array([0.0, h]))
            ax.plot_surface(body.center[0] + body.radius * np.cos(th),
                            body.center[1] + body.radius * np.sin(th), zz,
                            color="0.45", alpha=alpha, linewidth=0)
        else:
            c = _box_corners(body)
            for a in range(4):
                b = (a + 1) % 4
                xs = np.array([[c[a, 0], c[b, 0]], [c[a, 0], c[b, 0]]])
                ys = np.array([[c[a, 1], c[b, 1]], [c[a, 1], c[b, 1]]])
                zs = np.array([[0.0, 0.0], [h, h]])
                ax.plot_surface(xs, ys, zs, color="0.45", alpha=alpha, linewidth=0)
    for s in sc.spheres:
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 20), np.linspace(0, np.pi, 12))
        ax.plot_wireframe(s.center[0] + s.radius * np.cos(u) * np.sin(v),
                          s.center[1] + s.radius * np.sin(u) * np.sin(v),
                          s.center[2] + s.radius * np.cos(v), color="0.5", linewidth=0.4,
                          alpha=0.6 if s.physical else 0.35)
    p = record.positions
    for i, name in enumerate(record.ids):
        ax.plot(p[:, i, 0], p[:, i, 1], p[:, i, 2], color=colors[i], linewidth=1.3, label=name)
        ax.scatter(*p[0, i], color=colors[i], marker="o", s=14)
        ax.scatter(*sc.goals[i], color=colors[i], marker="x", s=22)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_zlim(*sc.limits.altitude)
    span = np.ptp(np.concatenate([p.reshape(-1, 3), sc.goals]), axis=0)
    dx, dy = max(span[0], 1e-3), max(span[1], 1e-3)
    dz = sc.limits.altitude[1] - sc.limits.altitude[0]
    ax.set_box_aspect((dx, dy, min(max(dz, 0.3 * max(dx, dy)), max(dx, dy))))
    ax.set_title(f"{sc.name}\n{record.formulation} / {record.solver}", fontsize="medium")
    _legend(ax, record.n_agents)
    return _save(fig, path)


def plot_top_view(record: RunRecord, path: str | Path) -> Path:
    """Top view (Figs. 13a, 15a, 19a): obstacles filled, their protected prisms dashed (the
    rotating square C_pz sweeps a circle of radius L_pz/2), spheres as circles."""
    sc = record.scenario
    fig = _new((7.0, 6.5))
    ax = fig.add_subplot()
    colors = _colors(record.n_agents)
    for body, spec in zip(sc.bodies, sc.obstacles):
        fc = "0.55" if spec.sensed else "0.8"
        if isinstance(body, Cylinder):
            ax.add_patch(Circle(tuple(body.center), body.radius, facecolor=fc, edgecolor="0.3"))
        else:
            ax.add_patch(Polygon(_box_corners(body), closed=True, facecolor=fc, edgecolor="0.3"))
        if spec.sensed:
            ax.add_patch(Circle(tuple(body.center), body.side / 2.0, fill=False,
                                linestyle="--", edgecolor="0.5", linewidth=0.8))
    for s in sc.spheres:
        ax.add_patch(Circle(tuple(s.center[:2]), s.radius, fill=False, edgecolor="0.35",
                            linestyle="-" if s.physical else ":"))
    p = record.positions
    for i, name in enumerate(record.ids):
        ax.plot(p[:, i, 0], p[:, i, 1], color=colors[i], linewidth=1.3, label=name)
        ax.plot(*p[0, i, :2], "o", color=colors[i], markersize=4)
        ax.plot(*sc.goals[i, :2], "x", color=colors[i], markersize=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, linewidth=0.4, alpha=0.5)
    ax.set_title(f"{sc.name}: top view", fontsize="medium")
    _legend(ax, record.n_agents)
    return _save(fig, path)


def _distance_figure(record: RunRecord, d: np.ndarray | None, path: str | Path, *, what: str,
                     ylabel: str, lines: np.ndarray, line_label: str, empty: str = "") -> Path:
    """Per-vehicle distance curves d (steps, agents) with the closest point marked and
    horizontal threshold lines; ``empty`` is shown instead when d is None."""
    fig = _new()
    ax = fig.add_subplot()
    if d is None:
        ax.text(0.5, 0.5, empty, ha="center", transform=ax.transAxes)
    else:
        colors = _colors(record.n_agents)
        for i, name in enumerate(record.ids):
            ax.plot(record.times, d[:, i], color=colors[i], linewidth=1.0, label=name)
        k = int(np.argmin(d.min(axis=1)))
        ax.plot(record.times[k], d[k].min(), "k.", markersize=8)
        ax.annotate(f"min {d[k].min():.3f} m", (record.times[k], d[k].min()),
                    textcoords="offset points", xytext=(6, -12), fontsize="small")
    for r in np.unique(lines):
        ax.axhline(r, color="red", linestyle="--", linewidth=1.0, label=f"{line_label} = {r:g} m")
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, linewidth=0.4, alpha=0.5)
    ax.set_title(f"{record.scenario.name}: {what}", fontsize="medium")
    _legend(ax, record.n_agents + 1)
    return _save(fig, path)


def plot_vehicle_distance(record: RunRecord, path: str | Path) -> Path:
    """Each vehicle's distance to its nearest other vehicle over time with the r_pz line
    (Figs. 14, 16a, 20a)."""
    d = nearest_vehicle_distance(record) if record.n_agents > 1 else None
    return _distance_figure(record, d, path, what="vehicle-vehicle distance",
                            ylabel="distance to nearest vehicle (m)", lines=record.scenario.r_pz,
                            line_label="r_pz", empty="one vehicle: no vehicle-vehicle distance")


def plot_obstacle_distance(record: RunRecord, path: str | Path) -> Path | None:
    """Each vehicle's distance to the nearest obstacle surface over time (Figs. 16b, 20b, 30);
    ``None`` (no file) when the scenario has no physical obstacle."""
    d = nearest_obstacle_distance(record)
    if not np.isfinite(d).any():
        return None
    return _distance_figure(record, d, path, what="vehicle-obstacle distance",
                            ylabel="distance to nearest obstacle surface (m)",
                            lines=record.scenario.radius, line_label="radius")


def write_plots(record: RunRecord, out_dir: str | Path) -> list[Path]:
    """All figures into ``out_dir``: trajectories_3d.png, top_view.png, vehicle_distance.png
    and, with obstacles, obstacle_distance.png. Returns the paths written."""
    out = Path(out_dir)
    written = [
        plot_trajectories_3d(record, out / "trajectories_3d.png"),
        plot_top_view(record, out / "top_view.png"),
        plot_vehicle_distance(record, out / "vehicle_distance.png"),
    ]
    obstacle = plot_obstacle_distance(record, out / "obstacle_distance.png")
    if obstacle is not None:
        written.append(obstacle)
    return written
