"""Figures of a run, like the paper's Figs. 13-20: 3D trajectories, the top view with the
obstacles, and the vehicle-vehicle and vehicle-obstacle distances over time.

Figures are drawn on ``matplotlib.figure.Figure`` with the Agg canvas, so importing this module
never changes the global matplotlib backend (notebooks keep theirs). ``figure_*`` build a
figure; ``plot_*`` write it to a file whose suffix (``.png``, ``.pdf`` or ``.svg``) sets the
format, cropped to what is drawn; :func:`write_plots` writes them all. PDF keeps its fonts as
TrueType and SVG its text as text, so both stay editable (journals reject Type 3 fonts).

Every figure explains its markers: start ``o``, goal ``x``, obstacles filled, their protected
prisms C_pz dashed, and the vehicles' protected spheres (radius r_pz) when drawn. The agents
are named in a legend up to :data:`LEGEND_MAX_AGENTS`, and by a colour bar beyond.

The distance curves are sampled every ``dt``; the marked minimum is the summary's own figure
(:func:`vo3d_opt.sim.metrics.closest_vehicle_approach`, continuous along each step), so it may
lie a little below the sampled curves. A swarm (more than :data:`SWARM_AGENTS` vehicles) is
drawn from samples of its record (:data:`PLOT_POINTS`, :data:`BAND_SAMPLES`): paths through
evenly spaced samples (straight chords between them), and distances as bands over the
vehicles: the least at every sample, the 5-95 % and the median at the drawn ones.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
from matplotlib import colormaps, rc_context
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Polygon
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import Bbox
from mpl_toolkits.mplot3d import Axes3D, proj3d
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from vo3d_opt.sim.metrics import (
    CHUNK_ELEMENTS,
    Approach,
    closest_obstacle_approach,
    closest_vehicle_approach,
    nearest_obstacle_distance,
    nearest_vehicle_distance,
    physical_obstacle_names,
)
from vo3d_opt.sim.simulator import RunRecord
from vo3d_opt.types import Box, Cylinder

#: File formats every figure can be written in (the file's suffix chooses).
FORMATS = ("png", "pdf", "svg")
#: Resolution (dots per inch) of PNG figures; PDF and SVG are vector graphics.
DEFAULT_DPI = 150
#: Above this many agents, a colour bar names them instead of a legend.
LEGEND_MAX_AGENTS = 12
#: Above this many agents the paths, starts and goals are drawn as one collection each (a
#: thousand separate lines take a matplotlib figure most of a minute).
SWARM_AGENTS = 100
#: A swarm's figures (more than SWARM_AGENTS) draw its paths through at most this many points
#: in all, each path sampled evenly in time (first and last sample kept), and its distances as
#: bands over the vehicles (their 5-95 % and median at most BAND_SAMPLES times, their least at
#: every sample): a 10,000-agent run of 2,600 steps has
#: 26 million positions (630 MB), which matplotlib cannot draw in a useful time.
PLOT_POINTS = 2_000_000
BAND_SAMPLES = 500
#: "closest": the protected spheres of the closest pair at its closest approach.
DEFAULT_ZONES = "closest"

#: 'closest', 'none' / None, times in s, or ZoneSnapshots already worked out.
Zones = str | Sequence[float] | Sequence["ZoneSnapshot"] | None
OBSTACLE_GREY, PRISM_GREY = "0.55", "0.35"


# ------------------------------------------------------------------------------- helpers


def agent_colors(n: int) -> list:
    """One colour per agent: tab10 / tab20 up to 20 agents, then evenly along turbo."""
    cmap = colormaps["tab10" if n <= 10 else "tab20" if n <= 20 else "turbo"]
    if n <= 20:
        return [cmap(i % cmap.N) for i in range(n)]
    return [cmap(x) for x in np.linspace(0.05, 0.95, n)]


def new_figure(figsize: tuple[float, float]) -> Figure:
    """A figure on its own Agg canvas (no pyplot, no global backend)."""
    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def figure_format(path: str | Path) -> str:
    """The format a path's suffix asks for; ValueError naming ``path`` for another suffix."""
    fmt = Path(path).suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise ValueError(
            f"path: {str(path)!r} must end in one of " + ", ".join(f".{f}" for f in FORMATS)
        )
    return fmt


def check_dpi(dpi: int) -> int:
    if isinstance(dpi, bool) or not isinstance(dpi, int) or not 10 <= dpi <= 2400:
        raise ValueError(f"dpi: {dpi!r} must be an integer between 10 and 2400")
    return dpi


def content_bbox(fig: Figure, pad: float = 0.06) -> Bbox:
    """What is drawn, in inches, plus ``pad``. Unlike ``bbox_inches="tight"``, a 3D axes counts
    by its box, ticks and labels, not by its whole rectangle, which the projected box fills only
    in part: cropping to it leaves no wide empty margins."""
    fig.draw_without_rendering()
    fig.set_layout_engine("none")  # keep this layout: another backend must not lay out anew
    renderer = cast(FigureCanvasAgg, fig.canvas).get_renderer()
    boxes: list[Bbox | None] = [a.get_window_extent(renderer) for a in [*fig.legends, *fig.texts]]
    for ax in fig.axes:
        if ax.name != "3d":
            boxes.append(ax.get_tightbbox(renderer))
            continue
        boxes.append(box_3d_extent(ax))
        boxes += [a.get_tightbbox(renderer) for a in (ax.title, ax.get_legend()) if a is not None]
    box = Bbox.union([b for b in boxes if b is not None and b.width > 0])
    return box.transformed(fig.dpi_scale_trans.inverted()).padded(pad)


def save_figure(fig: Figure, path: str | Path, dpi: int = DEFAULT_DPI) -> Path:
    """Write ``fig`` in the format of the path's suffix, cropped to what is drawn."""
    fmt = figure_format(path)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Text stays text in SVG and TrueType in PDF; no dates, so a file is reproducible.
    with rc_context({"svg.fonttype": "none", "pdf.fonttype": 42, "svg.hashsalt": "vo3d"}):
        fig.savefig(
            path,
            dpi=check_dpi(dpi),
            bbox_inches=content_bbox(fig),
            metadata={"pdf": {"CreationDate": None}, "svg": {"Date": None}}.get(fmt),
        )
    return path


def _xy(p: Sequence[float] | np.ndarray) -> tuple[float, float]:
    return float(p[0]), float(p[1])


def box_corners(box: Box) -> np.ndarray:
    """The box's four footprint corners (4, 2), counter-clockwise."""
    lx, ly = box.size / 2.0
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    local = np.array([[-lx, -ly], [lx, -ly], [lx, ly], [-lx, ly]])
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + box.center


def prism_margin(body: Cylinder | Box) -> float:
    """The least distance (m) from the body to the boundary of its protected prism C_pz: a
    vehicle outside C_pz is at least this far from the body. C_pz turns to face the vehicle, so
    horizontally it is the disc of radius L_pz/2 (section 4.1); vertically it reaches h_pz."""
    return float(
        min(body.side / 2.0 - body.footprint_extent() / 2.0, body.prism_height - body.height)
    )


def drawn_samples(n_samples: int, budget: int) -> np.ndarray:
    """Indices of at most ``budget`` (>= 2) samples of ``n_samples``, evenly spread, the first
    and the last kept (all of them when there are no more)."""
    if n_samples <= budget:
        return np.arange(n_samples)
    return np.unique(np.linspace(0, n_samples - 1, budget).round().astype(np.int64))


def drawn_positions(record: RunRecord) -> np.ndarray:
    """The positions the path figures draw: all of them, or a swarm's ``PLOT_POINTS``."""
    if record.n_agents <= SWARM_AGENTS:
        return record.positions
    budget = max(2, PLOT_POINTS // record.n_agents)
    return record.positions[drawn_samples(record.positions.shape[0], budget)]


def chunk_samples(record: RunRecord) -> int:
    """Samples of positions read per chunk of a record that may live in a file (the metrics'
    ``CHUNK_ELEMENTS``; ``RunRecord.drop_resident`` after each)."""
    return max(1, CHUNK_ELEMENTS // max(1, 3 * record.positions.shape[1]))


def position_bounds(record: RunRecord) -> np.ndarray:
    """(2, 3) the least and greatest coordinates of every position, read a chunk at a time."""
    p = record.positions
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    step = chunk_samples(record)
    for a in range(0, p.shape[0], step):
        part = p[a : a + step].reshape(-1, 3)
        lo, hi = np.minimum(lo, part.min(axis=0)), np.maximum(hi, part.max(axis=0))
        record.drop_resident()
    return np.stack([lo, hi])


def positions_at(record: RunRecord, t: float) -> np.ndarray:
    """(N, 3) positions at time t (linear between samples, held after the last one)."""
    times = record.times
    k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
    if k == len(times) - 1:
        return record.positions[k].copy()
    f = (t - times[k]) / (times[k + 1] - times[k])
    return record.positions[k] + f * (record.positions[k + 1] - record.positions[k])


# ------------------------------------------------------------------------- protected zones


@dataclass(frozen=True)
class ZoneSnapshot:
    """Vehicles whose protected spheres are drawn, and where they are at ``time``."""

    time: float
    agents: np.ndarray  # (k,) indices
    positions: np.ndarray  # (k, 3)
    label: str


def parse_zones(text: str) -> str | tuple[float, ...]:
    """The CLI's ``--zones``: 'closest', 'none', or times in s separated by commas."""
    text = text.strip().lower()
    if text in ("closest", "none"):
        return text
    try:
        times = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise ValueError(
            f"zones: {text!r} is neither 'closest', 'none' nor times in s such as '10,20.5'"
        ) from None
    if not all(math.isfinite(t) and t >= 0 for t in times):
        raise ValueError(f"zones: times must be finite and non-negative, got {text!r}")
    return times


def zone_snapshots(record: RunRecord, zones: Zones = DEFAULT_ZONES) -> list[ZoneSnapshot]:
    """What ``zones`` asks to draw: None / 'none' nothing; 'closest' the closest vehicle pair
    at its closest approach (a lone vehicle at its closest obstacle approach); times (s) every
    vehicle at each (held at the last sample after the run's end); snapshots, as they are."""
    if zones is None or zones == "none":
        return []
    if not isinstance(zones, str) and all(isinstance(z, ZoneSnapshot) for z in zones):
        return cast(list[ZoneSnapshot], list(zones))  # worked out already (by write_plots)
    if isinstance(zones, str):
        if zones != "closest":
            return zone_snapshots(record, parse_zones(zones))
        pair = closest_vehicle_approach(record)
        if pair is not None:
            who, what = [pair.agent, pair.other], "closest approach"
        else:
            pair = closest_obstacle_approach(record)
            if pair is None:
                return []
            who, what = [pair.agent], "closest obstacle approach"
        idx = np.array(who)
        return [
            ZoneSnapshot(
                pair.time,
                idx,
                positions_at(record, pair.time)[idx],
                f"protected zone r_pz at the\n{what} (t = {pair.time:.1f} s)",
            )
        ]
    out = []
    for t in zones:
        if isinstance(t, bool) or not isinstance(t, (int, float, np.floating, np.integer)):
            raise ValueError(f"zones: {t!r} is not a time in s")
        t = float(t)
        if not (math.isfinite(t) and t >= 0):
            raise ValueError(f"zones: times must be finite and non-negative, got {t!r}")
        idx = np.arange(record.n_agents)
        out.append(
            ZoneSnapshot(
                t, idx, positions_at(record, t)[idx], f"protected zones r_pz at t = {t:g} s"
            )
        )
    return out


# ----------------------------------------------------------------------- legends, colours


#: Outline of the protected spheres of the k-th snapshot (cycled): tells the times apart.
ZONE_DASHES = [(0, (4, 2)), (0, (1, 1.5)), (0, (6, 2, 1, 2)), (0, (8, 3))]


def zone_dash(k: int) -> tuple:
    return ZONE_DASHES[k % len(ZONE_DASHES)]


def _zone_handle(k: int) -> Line2D:
    """A vehicle (dot) and the outline of its protected sphere as the k-th snapshot draws it."""
    return Line2D(
        [],
        [],
        color="0.2",
        linestyle=zone_dash(k),
        linewidth=0.9,
        marker="o",
        markersize=5,
        markerfacecolor="0.5",
        markeredgecolor="k",
    )


def key_handles(
    record: RunRecord,
    snaps: Sequence[ZoneSnapshot],
    *,
    prisms: bool,
) -> tuple[list, list[str]]:
    """Legend entries explaining the markers and outlines (not the agents)."""
    sc = record.scenario
    handles: list = [
        Line2D([], [], marker="o", color="0.2", linestyle="none", markersize=5),
        Line2D([], [], marker="x", color="0.2", linestyle="none", markersize=6),
    ]
    labels = ["start", "goal"]
    if sc.bodies:
        handles.append(Patch(facecolor=OBSTACLE_GREY, edgecolor="0.3"))
        labels.append("obstacle")
        if prisms and sc.sensed.any():
            handles.append(Line2D([], [], color=PRISM_GREY, linestyle="--", linewidth=0.9))
            labels.append("protected prism C_pz\n(radius L_pz/2 about its axis)")
        if not sc.sensed.all():
            handles.append(Patch(facecolor="0.82", edgecolor="0.3"))
            labels.append("obstacle not sensed")
    if sc.spheres:
        handles.append(
            Line2D(
                [],
                [],
                marker="o",
                markersize=9,
                markerfacecolor="none",
                markeredgecolor="0.35",
                linestyle="none",
            )
        )
        labels.append("static sphere\n(dotted: not physical)")
    for k, snap in enumerate(snaps):
        handles.append(_zone_handle(k))
        labels.append(snap.label)
    return handles, labels


def _agent_colorbar(fig: Figure, record: RunRecord, colors: list, **where) -> None:
    """A colour bar naming the agents: their colours in scenario order, a few ids as ticks."""
    n = record.n_agents
    norm = BoundaryNorm(np.arange(n + 1) - 0.5, n)
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=ListedColormap(colors)), **where)
    ticks = np.unique(np.linspace(0, n - 1, min(n, 8)).round().astype(int))
    bar.set_ticks(ticks.tolist(), labels=[record.ids[i] for i in ticks])
    bar.minorticks_off()
    bar.ax.tick_params(labelsize="small")
    bar.set_label(f"agent ({n})", fontsize="small")


def agent_key(
    fig: Figure,
    ax: Axes,
    record: RunRecord,
    colors: list,
    *,
    handles=None,
    labels=None,
    pad: float = 0.02,
) -> None:
    """The agents named by a legend of their ids up to LEGEND_MAX_AGENTS, with the key
    (``handles``, ``labels``) after them; beyond, by a colour bar, the key below the axes."""
    n = record.n_agents
    handles, labels = list(handles or []), list(labels or [])
    if n <= LEGEND_MAX_AGENTS:
        agents = [Line2D([], [], color=c, linewidth=1.6) for c in colors]
        ax.legend(
            agents + handles,
            list(record.ids) + labels,
            fontsize="small",
            loc="upper left",
            bbox_to_anchor=(1.0 + pad, 1.0),
            borderaxespad=0.0,
            frameon=False,
        )
        return
    else:
        _agent_colorbar(fig, record, colors, ax=ax, shrink=0.8, pad=pad, fraction=0.04)
    if handles:
        fig.legend(
            handles,
            labels,
            loc="outside lower center",
            ncols=min(3, len(handles)),
            fontsize="small",
            frameon=False,
        )


# ------------------------------------------------------------------------------- 3D view


def _cylinder_3d(ax, body: Cylinder, h: float, alpha: float) -> None:
    th = np.linspace(0, 2 * np.pi, 40)
    x, y = body.center[0] + body.radius * np.cos(th), body.center[1] + body.radius * np.sin(th)
    tt, zz = np.meshgrid(th, np.array([0.0, h]))
    ax.plot_surface(
        body.center[0] + body.radius * np.cos(tt),
        body.center[1] + body.radius * np.sin(tt),
        zz,
        color=OBSTACLE_GREY,
        alpha=alpha,
        linewidth=0,
        shade=True,
    )
    ax.add_collection3d(
        Poly3DCollection(
            [np.column_stack([x, y, np.full_like(x, h)])],
            facecolor=OBSTACLE_GREY,
            alpha=alpha,
            linewidth=0,
        )
    )


def _box_3d(ax, body: Box, h: float, alpha: float) -> None:
    c = box_corners(body)
    faces = [np.column_stack([c, np.full(4, h)])]
    for a in range(4):
        b = (a + 1) % 4
        faces.append(np.array([[*c[a], 0.0], [*c[b], 0.0], [*c[b], h], [*c[a], h]]))
    ax.add_collection3d(
        Poly3DCollection(
            faces, facecolor=OBSTACLE_GREY, alpha=alpha, edgecolor="0.35", linewidth=0.3
        )
    )


def _sphere_3d(ax, center, radius: float, **kw) -> None:
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 19), np.linspace(0, np.pi, 10))
    ax.plot_wireframe(
        center[0] + radius * np.cos(u) * np.sin(v),
        center[1] + radius * np.sin(u) * np.sin(v),
        center[2] + radius * np.cos(v),
        **kw,
    )


def scene_bounds(record: RunRecord, snaps: Sequence[ZoneSnapshot] = ()) -> np.ndarray:
    """(2, 3) lower and upper corners of what a view shows: paths, goals, obstacles (up to the
    altitude ceiling), spheres and the drawn protected spheres."""
    sc = record.scenario
    pts = [position_bounds(record), sc.goals]
    z_top = sc.limits.altitude[1]
    for body in sc.bodies:
        r = body.side / 2.0
        top = min(body.height, z_top)
        pts.append(
            np.array(
                [
                    [body.center[0] - r, body.center[1] - r, 0.0],
                    [body.center[0] + r, body.center[1] + r, top],
                ]
            )
        )
    for s in sc.spheres:
        pts.append(np.asarray(s.center) + np.array([[-1.0], [1.0]]) * s.radius)
    for snap in snaps:
        r = record.scenario.r_pz[snap.agents][:, None]
        pts += [snap.positions - r, snap.positions + r]
    allp = np.concatenate(pts)
    return np.stack([allp.min(axis=0), allp.max(axis=0)])


def _equal_limits(
    lo: np.ndarray, hi: np.ndarray, *, pad: float = 0.03, min_z_ratio: float = 0.2
) -> tuple[np.ndarray, np.ndarray]:
    """Limits hugging [lo, hi] with a small pad; a flat scene's z range is widened (about its
    middle) to min_z_ratio of the horizontal span so the view does not collapse."""
    span = np.maximum(hi - lo, 1e-3)
    lo, hi = lo - pad * span, hi + pad * span
    horiz = max(hi[0] - lo[0], hi[1] - lo[1])
    need = min_z_ratio * horiz - (hi[2] - lo[2])
    if need > 0:
        lo[2], hi[2] = lo[2] - need / 2, hi[2] + need / 2
    return lo, hi


def figure_trajectories_3d(record: RunRecord, *, zones: Zones = DEFAULT_ZONES) -> Figure:
    """3D flight paths with cylinders, boxes and spheres (Figs. 13b, 15b), equal scale on all
    three axes, the box hugging the scene, the keys placed around the projected box."""
    sc = record.scenario
    snaps = zone_snapshots(record, zones)
    lo, hi = _equal_limits(*scene_bounds(record, snaps))
    fig = Figure(figsize=(7.0, 5.2))
    FigureCanvasAgg(fig)
    ax = cast(Axes3D, fig.add_axes((0.0, 0.0, 1.0, 1.0), projection="3d", proj_type="ortho"))
    colors = agent_colors(record.n_agents)
    z_top = sc.limits.altitude[1]
    for body, sensed in zip(sc.bodies, sc.sensed, strict=False):
        h = min(body.height, z_top)
        alpha = 0.35 if sensed else 0.15
        if isinstance(body, Cylinder):
            _cylinder_3d(ax, body, h, alpha)
        else:
            _box_3d(ax, body, h, alpha)
    for s in sc.spheres:
        _sphere_3d(
            ax,
            s.center,
            s.radius,
            color="0.45",
            linewidth=0.4,
            alpha=0.6 if s.physical else 0.3,
            linestyle="-" if s.physical else ":",
        )
    p = drawn_positions(record)
    if record.n_agents > SWARM_AGENTS:  # one artist per kind, not per agent: seconds, not minutes
        paths = Line3DCollection(list(p.transpose(1, 0, 2)), colors=colors, linewidths=0.6)
        ax.add_collection3d(paths)
        for point, marker, size in ((p[0], "o", 4), (sc.goals, "x", 6)):
            ax.scatter(
                point[:, 0],
                point[:, 1],
                point[:, 2],
                color=colors,
                marker=marker,
                s=size,
                depthshade=False,
            )
    for i in range(record.n_agents if record.n_agents <= SWARM_AGENTS else 0):
        ax.plot(p[:, i, 0], p[:, i, 1], p[:, i, 2], color=colors[i], linewidth=1.2)
        for point, marker, size in ((p[0, i], "o", 14), (sc.goals[i], "x", 22)):
            ax.scatter(
                point[0],
                point[1],
                point[2],
                color=colors[i],
                marker=marker,
                s=size,
                depthshade=False,
            )
    for k, snap in enumerate(snaps):
        for i, c in zip(snap.agents, snap.positions, strict=False):
            _sphere_3d(
                ax,
                c,
                float(sc.r_pz[i]),
                color=colors[i],
                linewidth=0.5,
                alpha=0.55,
                linestyle=zone_dash(k),
            )
            ax.scatter(
                c[0], c[1], c[2], color=colors[i], edgecolor="k", s=30, depthshade=False, zorder=5
            )
    ax.set(
        xlim=(lo[0], hi[0]),
        ylim=(lo[1], hi[1]),
        zlim=(lo[2], hi[2]),
        xlabel="x (m)",
        ylabel="y (m)",
        zlabel="z (m)",
    )
    ax.set_box_aspect(tuple(hi - lo))
    ax.view_init(elev=28, azim=-60)
    ax.tick_params(labelsize="small", pad=0)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5 if axis is not ax.zaxis else 4))
    handles, labels = key_handles(record, snaps, prisms=False)
    _keys_around_box(
        fig,
        ax,
        record,
        colors,
        handles,
        labels,
        title=f"{sc.name} ({record.formulation} / {record.solver})",
    )
    return fig


def box_3d_extent(ax) -> Bbox:
    """Display extent of a 3D axes' box (its eight projected corners) with its axes' ticks and
    labels, as last drawn."""
    renderer = ax.figure.canvas.get_renderer()
    limits = (ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d())
    corners = np.array(np.meshgrid(*limits)).reshape(3, -1)
    xs, ys, _ = proj3d.proj_transform(*corners, ax.get_proj())
    pts = ax.transData.transform(np.column_stack([xs, ys]))
    boxes = [Bbox([pts.min(axis=0), pts.max(axis=0)])]
    boxes += [a.get_tightbbox(renderer) for a in (ax.xaxis, ax.yaxis, ax.zaxis)]
    return Bbox.union(boxes)


def _keys_around_box(
    fig: Figure,
    ax,
    record: RunRecord,
    colors: list,
    handles: list,
    labels: list[str],
    *,
    title: str,
    gap: float = 0.015,
) -> None:
    """Title above the projected 3D box, agents (legend or colour bar) at its right, the key
    below it: placed from the drawn box, so cropping to the content leaves no empty margin."""
    fig.draw_without_rendering()
    (x0, y0), (x1, y1) = fig.transFigure.inverted().transform(box_3d_extent(ax).get_points())
    fig.text((x0 + x1) / 2, y1 + gap, title, ha="center", va="bottom", fontsize="medium")
    if record.n_agents <= LEGEND_MAX_AGENTS:
        fig.legend(
            [Line2D([], [], color=c, linewidth=1.6) for c in colors],
            record.ids,
            loc="upper left",
            bbox_to_anchor=(x1 + gap, y1),
            fontsize="small",
            frameon=False,
            borderaxespad=0.0,
        )
    else:
        h = y1 - y0
        _agent_colorbar(
            fig, record, colors, cax=fig.add_axes((x1 + 2 * gap, y0 + 0.1 * h, 0.022, 0.8 * h))
        )
    if handles:
        fig.legend(
            handles,
            labels,
            loc="upper center",
            bbox_to_anchor=((x0 + x1) / 2, y0 - gap),
            ncols=min(3, len(handles)),
            fontsize="small",
            frameon=False,
            borderaxespad=0.0,
        )


# ------------------------------------------------------------------------------- top view


def draw_obstacles_2d(ax: Axes, record: RunRecord) -> None:
    """Obstacles filled (lighter when not sensed), protected prisms dashed (the rotating square
    C_pz sweeps a circle of radius L_pz/2), spheres as circles (dotted: not physical)."""
    sc = record.scenario
    for body, sensed in zip(sc.bodies, sc.sensed, strict=False):
        fc = OBSTACLE_GREY if sensed else "0.82"
        if isinstance(body, Cylinder):
            ax.add_patch(Circle(_xy(body.center), body.radius, facecolor=fc, edgecolor="0.3"))
        else:
            ax.add_patch(Polygon(box_corners(body), closed=True, facecolor=fc, edgecolor="0.3"))
        if sensed:
            ax.add_patch(
                Circle(
                    _xy(body.center),
                    body.side / 2.0,
                    fill=False,
                    linestyle="--",
                    edgecolor=PRISM_GREY,
                    linewidth=0.9,
                )
            )
    for s in sc.spheres:
        ax.add_patch(
            Circle(
                _xy(s.center),
                s.radius,
                fill=False,
                edgecolor="0.35",
                linestyle="-" if s.physical else ":",
            )
        )


def figure_top_view(record: RunRecord, *, zones: Zones = DEFAULT_ZONES) -> Figure:
    """Top view (Figs. 13a, 15a, 19a): paths over the obstacles and their protected prisms."""
    sc = record.scenario
    snaps = zone_snapshots(record, zones)
    fig = new_figure((7.0, 5.6))
    ax = fig.add_subplot()
    colors = agent_colors(record.n_agents)
    draw_obstacles_2d(ax, record)
    p = drawn_positions(record)
    if record.n_agents > SWARM_AGENTS:  # one artist per kind, not per agent
        paths = LineCollection(list(p[:, :, :2].transpose(1, 0, 2)), colors=colors, linewidths=0.6)
        ax.add_collection(paths)
        ax.scatter(p[0, :, 0], p[0, :, 1], color=colors, marker="o", s=4)
        ax.scatter(sc.goals[:, 0], sc.goals[:, 1], color=colors, marker="x", s=6)
    for i in range(record.n_agents if record.n_agents <= SWARM_AGENTS else 0):
        ax.plot(p[:, i, 0], p[:, i, 1], color=colors[i], linewidth=1.2)
        ax.plot(*p[0, i, :2], "o", color=colors[i], markersize=4)
        ax.plot(*sc.goals[i, :2], "x", color=colors[i], markersize=6)
    for k, snap in enumerate(snaps):
        for i, c in zip(snap.agents, snap.positions, strict=False):
            ax.add_patch(
                Circle(
                    _xy(c),
                    float(sc.r_pz[i]),
                    fill=False,
                    edgecolor=colors[i],
                    linewidth=0.9,
                    linestyle=zone_dash(k),
                )
            )
            ax.plot(*c[:2], "o", color=colors[i], markeredgecolor="k", markersize=6)
    lo, hi = scene_bounds(record, snaps)
    pad = 0.03 * max(hi[0] - lo[0], hi[1] - lo[1], 1e-3)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, linewidth=0.4, alpha=0.5)
    ax.set_title(f"{sc.name}: top view", fontsize="medium")
    handles, labels = key_handles(record, snaps, prisms=True)
    agent_key(fig, ax, record, colors, handles=handles, labels=labels)
    return fig


# ------------------------------------------------------------------------------ distances


def distance_samples(record: RunRecord) -> np.ndarray | None:
    """The samples at which a distance figure draws a swarm's bands: None (every vehicle's own
    curve) up to SWARM_AGENTS vehicles, else ``BAND_SAMPLES`` of them."""
    if record.n_agents <= SWARM_AGENTS:
        return None
    return drawn_samples(record.positions.shape[0], BAND_SAMPLES)


def swarm_bands(
    record: RunRecord, distances: Callable[[RunRecord, np.ndarray], np.ndarray], samples: np.ndarray
) -> np.ndarray:
    """(T+1, 4): at every sample the least of the vehicles' distances (``distances(record,
    [k])``: one row of N), and at ``samples`` their 5, 50 and 95 % (NaN elsewhere): one sample
    at a time, so that no (T+1, N) array is built; vehicles without a distance (inf) left out."""
    T = record.positions.shape[0]
    out = np.full((T, 4), np.nan)
    banded = np.zeros(T, dtype=bool)
    banded[samples] = True
    step = chunk_samples(record)
    for k in range(T):
        d = distances(record, np.array([k]))[0]
        d = d[np.isfinite(d)]
        if d.size:
            out[k, 0] = d.min()
            if banded[k]:
                out[k, 1:] = np.percentile(d, [5.0, 50.0, 95.0])
        if k % step == step - 1:
            record.drop_resident()
    return out


def _distance_figure(
    record: RunRecord,
    d: np.ndarray,
    closest: Approach,
    other: str,
    *,
    what: str,
    ylabel: str,
    lines: dict[float, str],
    samples: np.ndarray | None = None,
) -> Figure:
    """Per-vehicle distance curves d (samples, agents), or a swarm's bands over the vehicles
    (``swarm_bands``' d, its percentiles drawn at ``samples``), the closest approach marked with
    the summary's figure, and horizontal reference lines {value: label}."""
    fig = new_figure((7.0, 4.2))
    ax = fig.add_subplot()
    colors = agent_colors(record.n_agents)
    handles: list[Any] = []
    labels: list[str] = []
    if samples is None:
        width = 1.0 if record.n_agents <= LEGEND_MAX_AGENTS else 0.6
        for i in range(record.n_agents):
            ax.plot(record.times, d[:, i], color=colors[i], linewidth=width)
    else:
        handles, labels = _bands(ax, record.times, d, samples)
    for value, label in sorted(lines.items()):
        handles.append(ax.axhline(value, color="red", linestyle="--", linewidth=1.0))
        labels.append(label)
    name = record.ids[closest.agent]
    handles.append(ax.plot(closest.time, closest.distance, "k.", markersize=9)[0])
    labels.append(f"closest approach ({name}, {other})")
    ax.annotate(
        f"min {closest.distance:.3f} m",
        (closest.time, closest.distance),
        textcoords="offset points",
        xytext=(6, -13),
        fontsize="small",
    )
    ax.set_ylim(bottom=0.0)
    ax.set_xlim(record.times[0], record.times[-1])
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, linewidth=0.4, alpha=0.5)
    ax.set_title(f"{record.scenario.name}: {what}", fontsize="medium")
    if samples is None:
        agent_key(fig, ax, record, colors, handles=handles, labels=labels)
    else:  # no vehicle has a curve of its own: the bands' key, no colour bar
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small")
    return fig


def _bands(
    ax: Axes, times: np.ndarray, d: np.ndarray, samples: np.ndarray
) -> tuple[list[Any], list[str]]:
    """A swarm's distances (``swarm_bands``' d) drawn: the least over the vehicles at every
    sample, the 5-95 % band and the median at ``samples``; the key's entries."""
    t = times[samples]
    band = ax.fill_between(t, d[samples, 1], d[samples, 3], color="tab:blue", alpha=0.25, lw=0)
    (median,) = ax.plot(t, d[samples, 2], color="tab:blue", linewidth=1.0)
    (low,) = ax.plot(times, d[:, 0], color="k", linewidth=0.8)
    return [low, band, median], ["least over the vehicles", "5-95 % of the vehicles", "median"]


def figure_vehicle_distance(record: RunRecord) -> Figure | None:
    """Each vehicle's distance to its nearest other vehicle over time with the r_pz line
    (Figs. 14, 16a, 20a); None for a single vehicle."""
    closest = closest_vehicle_approach(record)
    if closest is None:
        return None
    lines = {float(r): f"r_pz = {r:g} m" for r in np.unique(record.scenario.r_pz)}
    samples = distance_samples(record)
    d = (
        nearest_vehicle_distance(record)
        if samples is None
        else swarm_bands(record, nearest_vehicle_distance, samples)
    )
    return _distance_figure(
        record,
        d,
        closest,
        record.ids[closest.other],
        what="vehicle-vehicle distance",
        ylabel="distance to nearest vehicle (m)",
        lines=lines,
        samples=samples,
    )


def obstacle_margins(record: RunRecord) -> np.ndarray:
    """The prism margin of every obstacle the metrics count (bodies, then physical spheres:
    radius + margin is their protected zone, so their margin is the gap to it)."""
    sc = record.scenario
    return np.array(
        [prism_margin(b) for b in sc.bodies] + [s.r_pz - s.radius for s in sc.spheres if s.physical]
    )


def figure_obstacle_distance(record: RunRecord) -> Figure | None:
    """Each vehicle's distance to the nearest obstacle surface over time (Figs. 16b, 20b, 30),
    with the prism margin (a vehicle outside C_pz is at least that far from the body); None
    without a physical obstacle."""
    closest = closest_obstacle_approach(record)
    if closest is None:
        return None
    margins = np.unique(obstacle_margins(record).round(9))
    if len(margins) > 3:  # many different margins: the smallest is the one that binds
        margins = margins[:1]
        lines = {float(margins[0]): f"smallest prism margin = {margins[0]:g} m"}
    else:
        lines = {float(m): f"prism margin = {m:g} m" for m in margins}
    other = physical_obstacle_names(record)[closest.other]
    samples = distance_samples(record)
    d = (
        nearest_obstacle_distance(record)
        if samples is None
        else swarm_bands(record, nearest_obstacle_distance, samples)
    )
    return _distance_figure(
        record,
        d,
        closest,
        other,
        what="vehicle-obstacle distance",
        ylabel="distance to nearest obstacle surface (m)",
        lines=lines,
        samples=samples,
    )


# ---------------------------------------------------------------------------- file output


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
