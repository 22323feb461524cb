"""A swarm's top view (more than LEGEND_MAX_AGENTS vehicles): what a reader can use when a
thousand paths would be spaghetti.

* occupancy: where the vehicles flew, as the time they spent over each cell of the map
  (vehicle-seconds per square metre; arrived vehicles hovering at their goals left out);
* a named sample of paths (SAMPLE_PATHS): the closest pair's two vehicles and others spread
  through the scenario's order;
* the closest pairs (``scene.CLOSEST_PAIRS``), numbered where they met, with the same numbers
  on the vehicle-distance plot;
* the closest approach enlarged in a panel at the right: the two vehicles' protected spheres,
  every vehicle there at that moment and the paths through that window.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.sim.metrics import Approach
from vo3d_opt.sim.record import RunRecord

from .keys import key_handles, marker_handle
from .labels import place_label
from .scene import (
    DEFAULT_ZONES,
    Zones,
    ZoneSnapshot,
    chunk_samples,
    closest_pairs,
    drawn_indices,
    positions_at,
    scene_bounds,
    zone_snapshots,
)
from .style import DENSITY_CMAP, PALETTE, new_figure, settle, styled
from .topview import (
    draw_obstacles_2d,
    draw_zones_2d,
    frame_map,
    frame_top_view,
    label_obstacles,
)

with needs("sim", "plotting"):
    from matplotlib.axes import Axes
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Rectangle
    from matplotlib.transforms import ScaledTranslation

#: Paths drawn and named.
SAMPLE_PATHS = 6
#: Cells of the occupancy map along its longer side.
DENSITY_CELLS = 60
#: Width (in) of the column at the right of the map: the enlarged window and the key.
SIDE_WIDTH = 3.4
#: The enlarged window's half side, in protected radii r_pz (at least).
ZOOM_RADII = 3.0


def sample_agents(record: RunRecord, pairs: list[Approach], count: int = SAMPLE_PATHS) -> list[int]:
    """``count`` vehicles whose paths are drawn: the closest pair's, then others evenly spread
    through the scenario's order."""
    chosen: list[int] = []
    if pairs:
        chosen += [pairs[0].agent, pairs[0].other]
    for i in np.linspace(0, record.n_agents - 1, count + 2).round().astype(int):
        if len(chosen) >= count:
            break
        if int(i) not in chosen:
            chosen.append(int(i))
    return chosen[:count]


@dataclass(frozen=True)
class Occupancy:
    """Time spent over each cell of a map: ``values`` (ny, nx) in vehicle-seconds per m²,
    between the cell edges ``x_edges`` (nx + 1) and ``y_edges`` (ny + 1), m."""

    values: np.ndarray
    x_edges: np.ndarray
    y_edges: np.ndarray


@dataclass(frozen=True)
class Window:
    """A square of the map: its centre (x, y) and half side (m)."""

    centre: np.ndarray
    half: float


def occupancy(record: RunRecord, lo: np.ndarray, hi: np.ndarray) -> Occupancy:
    """The time flying vehicles (not yet arrived) spent over each cell of [lo, hi] (x, y), from
    the drawn samples, each standing for the time to the next drawn one; read a chunk at a
    time."""
    cell = max(hi[0] - lo[0], hi[1] - lo[1]) / DENSITY_CELLS
    xe = np.arange(lo[0], hi[0] + cell, cell)
    ye = np.arange(lo[1], hi[1] + cell, cell)
    idx = drawn_indices(record)
    weight = np.diff(record.times[idx], append=record.times[idx[-1]])
    if idx.size > 1:
        weight[-1] = weight[-2]
    total = np.zeros((xe.size - 1, ye.size - 1))
    step = chunk_samples(record)
    for a in range(0, idx.size, step):
        part = idx[a : a + step]
        p = record.positions[part]
        flying = ~record.arrived[part]
        w = np.broadcast_to(weight[a : a + step, None], flying.shape)[flying]
        h, _, _ = np.histogram2d(p[..., 0][flying], p[..., 1][flying], bins=(xe, ye), weights=w)
        total += h
        record.drop_resident()
    return Occupancy(total.T / cell**2, xe, ye)


def draw_density(fig: Figure, ax: Axes, record: RunRecord) -> Any:
    """The occupancy map under everything, empty cells left white, and its colour bar below."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    occ = occupancy(record, np.array([x0, y0]), np.array([x1, y1]))
    shown = np.ma.masked_less_equal(occ.values, 0.0)
    # a few cells where vehicles waited would wash the rest out: the scale ends at the 99th
    # percentile of the cells flown over, the bar's arrow standing for the cells beyond
    top = float(np.percentile(shown.compressed(), 99.0)) if shown.count() else 1.0
    image = ax.pcolormesh(
        occ.x_edges,
        occ.y_edges,
        shown,
        shading="flat",
        zorder=0,
        rasterized=True,
        cmap=DENSITY_CMAP,
        vmin=0.0,
        vmax=top,
    )
    under = ax.transAxes + ScaledTranslation(0.0, -0.72, fig.dpi_scale_trans)  # below x label
    cax = ax.inset_axes((0.1, 0.0, 0.8, 0.035), transform=under)
    beyond = shown.count() and float(shown.max()) > top
    bar = fig.colorbar(
        image, cax=cax, orientation="horizontal", extend="max" if beyond else "neither"
    )
    bar.set_label("occupancy: time flying vehicles spent over each m² (vehicle·s/m²)")
    return image


def draw_sample_paths(ax: Axes, record: RunRecord, agents: list[int]) -> list[Line2D]:
    """The sample's paths in the palette's colours, start o and goal x; the key's lines."""
    p = record.positions[drawn_indices(record)]
    handles = []
    for k, i in enumerate(agents):
        color = PALETTE[k % len(PALETTE)]
        (line,) = ax.plot(p[:, i, 0], p[:, i, 1], color=color, linewidth=1.6, zorder=3)
        line.set_gid(record.ids[i])
        ax.scatter([p[0, i, 0]], [p[0, i, 1]], color=color, marker="o", s=22, zorder=4)
        g = record.scenario.goals[i]
        ax.scatter([g[0]], [g[1]], color=color, marker="x", s=30, linewidths=1.6, zorder=4)
        handles.append(line)
    return handles


def pair_points(record: RunRecord, pairs: list[Approach]) -> np.ndarray:
    """(k, 3) where each pair was at its closest approach: the middle of its two vehicles."""
    out = []
    for a in pairs:
        p = positions_at(record, a.time)
        out.append(0.5 * (p[a.agent] + p[a.other]))
    return np.array(out).reshape(-1, 3)


def mark_pairs_2d(ax: Axes, record: RunRecord, pairs: list[Approach]) -> list[Any]:
    """Each closest pair's meeting point, a ring numbered in order (layout settled)."""
    pts = pair_points(record, pairs)
    ax.scatter(
        pts[:, 0], pts[:, 1], s=70, facecolors="none", edgecolors="k", linewidths=1.4, zorder=5
    )
    return [
        place_label(
            ax, str(k + 1), (x, y), base=5.0, prefer=math.pi / 4, fontsize=9, fontweight="bold"
        )
        for k, (x, y, _) in enumerate(pts)
    ]


def zoom_window(record: RunRecord, pair: Approach) -> Window:
    """The enlarged window around the closest approach."""
    p = positions_at(record, pair.time)
    a, b = p[pair.agent, :2], p[pair.other, :2]
    r = float(max(record.scenario.r_pz[pair.agent], record.scenario.r_pz[pair.other]))
    half = max(ZOOM_RADII * r, 0.5 * float(np.hypot(*(a - b))) + 1.5 * r)
    return Window(0.5 * (a + b), half)


def _worth_enlarging(record: RunRecord, pair: Approach, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether the closest approach is small on the map: its window under a quarter of it."""
    return 2.0 * zoom_window(record, pair).half < 0.25 * max(hi[0] - lo[0], hi[1] - lo[1])


def draw_zoom(
    ax: Axes, record: RunRecord, pair: Approach, snap: ZoneSnapshot, colors: dict[int, str]
) -> None:
    """The closest approach enlarged: paths through the window thin and grey, the pair's in
    their colours, every vehicle there at that moment, and the pair's protected spheres."""
    window = zoom_window(record, pair)
    centre, half = window.centre, window.half
    p = record.positions[drawn_indices(record)]
    near = np.any(np.all(np.abs(p[..., :2] - centre) < 2 * half, axis=-1), axis=0)
    others = [i for i in np.flatnonzero(near) if i not in (pair.agent, pair.other)]
    if others:
        ax.add_collection(
            LineCollection(
                list(p[:, others, :2].transpose(1, 0, 2)), colors="0.6", linewidths=0.8, zorder=1
            )
        )
    now = positions_at(record, pair.time)
    ax.scatter(now[others, 0], now[others, 1], s=14, color="0.45", zorder=3)
    draw_obstacles_2d(ax, record, prisms=False)
    for i in (pair.agent, pair.other):
        ax.plot(p[:, i, 0], p[:, i, 1], color=colors[i], linewidth=1.6, zorder=2)
    draw_zones_2d(ax, record, [snap], [colors.get(i, "0.45") for i in range(record.n_agents)])
    frame_map(ax, centre - half, centre + half)
    ids = record.ids
    ax.set_title(
        f"1: {ids[pair.agent]}–{ids[pair.other]}, {pair.distance:.2f} m\n"
        f"at t = {pair.time:.1f} s (enlarged)",
        fontsize=10,
    )


def _pair_rows(record: RunRecord, pairs: list[Approach]) -> tuple[list, list[str]]:
    """The numbered closest pairs as key entries: number, pair, distance, time."""
    ids = record.ids
    handles: list = [marker_handle("o", 8, markerfacecolor="none", markeredgecolor="k")]
    labels = ["closest pairs where they met:"]
    for k, a in enumerate(pairs):
        handles.append(Line2D([], [], linestyle="none"))
        labels.append(
            f"{k + 1}: {ids[a.agent]}–{ids[a.other]}, {a.distance:.2f} m, t = {a.time:.1f} s"
        )
    return handles, labels


def _closest_snapshot(record: RunRecord, pair: Approach) -> ZoneSnapshot:
    idx = np.array([pair.agent, pair.other])
    return ZoneSnapshot(
        pair.time,
        idx,
        positions_at(record, pair.time)[idx],
        f"protected zone r_pz at the\nclosest approach (t = {pair.time:.1f} s)",
    )


def _zoom_key() -> tuple[list, list[str]]:
    """Key entries of the enlarged window and what it alone draws."""
    handles = [
        Patch(fill=False, edgecolor="k"),
        marker_handle("o", 4, color="0.45"),
        Line2D([], [], color="0.6", linewidth=0.8),
    ]
    labels = [
        "window enlarged at the right",
        "(enlarged) other vehicles then",
        "(enlarged) other paths there",
    ]
    return handles, labels


def _enlarge(
    ax: Axes, zoom: Axes, record: RunRecord, pair: Approach, colors: dict[int, str]
) -> None:
    """The closest approach enlarged in ``zoom``, its window outlined on the map ``ax``."""
    draw_zoom(zoom, record, pair, _closest_snapshot(record, pair), colors)
    window = zoom_window(record, pair)
    side = 2.0 * window.half
    corner = (float(window.centre[0] - window.half), float(window.centre[1] - window.half))
    ax.add_patch(Rectangle(corner, side, side, fill=False, edgecolor="k", linewidth=0.9, zorder=5))


def _sample_key(record: RunRecord, agents: list[int], lines: list) -> tuple[list, list[str]]:
    """The sample's paths named, the first saying what they are."""
    labels = [record.ids[i] for i in agents]
    labels[0] += f" (a sample of {len(agents)} paths)"
    return list(lines), labels


@dataclass(frozen=True)
class _Panels:
    """A swarm's top-view figure: the map, the enlarged window (None when the closest approach
    is large enough on the map) and the axes holding the key."""

    fig: Figure
    map: Axes
    zoom: Axes | None
    key: Axes


def _panels(record: RunRecord, snaps: list[ZoneSnapshot], pairs: list[Approach]) -> _Panels:
    """The map sized to the scene's aspect, the window and the key in a column at its right."""
    lo, hi = scene_bounds(record, snaps)
    aspect = max(hi[1] - lo[1], 1e-3) / max(hi[0] - lo[0], 1e-3)
    map_h = 4.8 if aspect >= 0.5 else 2.4
    map_w = min(map_h / aspect, 8.0)
    fig = new_figure((map_w + SIDE_WIDTH + 1.0, map_h + 1.9))
    grid = fig.add_gridspec(2, 2, width_ratios=[map_w, SIDE_WIDTH], height_ratios=[1.0, 1.25])
    enlarged = bool(pairs) and _worth_enlarging(record, pairs[0], lo, hi)
    map_ax = fig.add_subplot(grid[:, 0])  # first: fig.axes[0] is the map, as in a small run's
    zoom = fig.add_subplot(grid[0, 1]) if enlarged else None
    key = fig.add_subplot(grid[1, 1] if enlarged else grid[:, 1])
    key.axis("off")
    return _Panels(fig, map_ax, zoom, key)


@styled
def figure_swarm_top_view(record: RunRecord, *, zones: Zones = DEFAULT_ZONES) -> Figure:
    """A swarm's top view (module docstring): occupancy, a named sample of paths, the numbered
    closest pairs, the named obstacles and the closest approach enlarged."""
    snaps = zone_snapshots(record, zones)
    pairs = closest_pairs(record)
    panels = _panels(record, snaps, pairs)
    ax = panels.map
    agents = sample_agents(record, pairs)
    colors = {i: PALETTE[k % len(PALETTE)] for k, i in enumerate(agents)}
    draw_obstacles_2d(ax, record)
    handles, labels = _sample_key(record, agents, draw_sample_paths(ax, record, agents))
    draw_zones_2d(ax, record, snaps, [colors.get(i, "0.3") for i in range(record.n_agents)])
    frame_top_view(ax, record, snaps)
    draw_density(panels.fig, ax, record)
    ax.set_title(f"{record.scenario.name}: top view of {record.n_agents} vehicles")
    parts = [key_handles(record, snaps, prisms=True)]
    if panels.zoom is not None:
        _enlarge(ax, panels.zoom, record, pairs[0], colors)
        parts.append(_zoom_key())
    if pairs:
        parts.append(_pair_rows(record, pairs))
    for more, names in parts:
        handles += more
        labels += names
    panels.key.legend(
        handles, labels, loc="upper left", frameon=False, borderaxespad=0.0, fontsize=8.5
    )
    settle(panels.fig)
    label_obstacles(ax, record)
    if pairs:
        mark_pairs_2d(ax, record, pairs)
    return panels.fig
