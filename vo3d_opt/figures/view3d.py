"""The 3D view (the paper's Figs. 13b, 15b, 19b): paths among the cylinders, boxes and spheres at
equal scale on all three axes, the obstacles named where the names fit; a swarm's as a named
sample of paths over every vehicle's start."""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.sim.record import RunRecord
from vo3d_opt.types import Box, Cylinder

from .keys import agent_handles, key_handles, marker_handle, zone_dash
from .labels import place_label
from .scene import (
    DEFAULT_ZONES,
    Zones,
    ZoneSnapshot,
    box_corners,
    closest_pairs,
    drawn_indices,
    obstacle_names,
    scene_bounds,
    zone_snapshots,
)
from .style import (
    LEGEND_MAX_AGENTS,
    OBSTACLE_GREY,
    PALETTE,
    agent_styles,
    box_3d_extent,
    new_figure,
    settle,
    styled,
)
from .swarm import sample_agents

with needs("sim", "plotting"):
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator
    from mpl_toolkits.mplot3d import Axes3D, proj3d
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

#: The ground of the obstacles' names, which may lie over the translucent obstacles.
NAME_GROUND = {"boxstyle": "square,pad=0.1", "facecolor": "white", "alpha": 0.75, "linewidth": 0}
#: How far (points) from an obstacle's top its name may go in the 3D view.
NAME_REACH = 12.0
#: Above this many obstacles their names are left to the top view (they would not fit).
NAMED_3D = 12


def _cylinder_3d(ax: Any, body: Cylinder, h: float, alpha: float) -> list[Any]:
    th = np.linspace(0, 2 * np.pi, 40)
    x, y = body.center[0] + body.radius * np.cos(th), body.center[1] + body.radius * np.sin(th)
    tt, zz = np.meshgrid(th, np.array([0.0, h]))
    side = ax.plot_surface(
        body.center[0] + body.radius * np.cos(tt),
        body.center[1] + body.radius * np.sin(tt),
        zz,
        color=OBSTACLE_GREY,
        alpha=alpha,
        linewidth=0,
        shade=True,
    )
    top = Poly3DCollection([np.column_stack([x, y, np.full_like(x, h)])], linewidth=0)
    top.set(facecolor=OBSTACLE_GREY, alpha=alpha)
    ax.add_collection3d(top)
    return [side, top]


def _box_3d(ax: Any, body: Box, h: float, alpha: float) -> list[Any]:
    c = box_corners(body)
    faces = [np.column_stack([c, np.full(4, h)])]
    for a in range(4):
        b = (a + 1) % 4
        faces.append(np.array([[*c[a], 0.0], [*c[b], 0.0], [*c[b], h], [*c[a], h]]))
    poly = Poly3DCollection(faces, edgecolor="0.35", linewidth=0.3)
    poly.set(facecolor=OBSTACLE_GREY, alpha=alpha)
    ax.add_collection3d(poly)
    return [poly]


def _sphere_3d(ax: Any, center: np.ndarray, radius: float, **kw: Any) -> None:
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 19), np.linspace(0, np.pi, 10))
    ax.plot_wireframe(
        center[0] + radius * np.cos(u) * np.sin(v),
        center[1] + radius * np.sin(u) * np.sin(v),
        center[2] + radius * np.cos(v),
        **kw,
    )


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
        ground = lo[2] >= 0.0
        lo[2], hi[2] = lo[2] - need / 2, hi[2] + need / 2
        if ground and lo[2] < 0.0:  # widened upwards only: nothing flies below the ground
            lo[2], hi[2] = 0.0, hi[2] - lo[2]
    return lo, hi


def _obstacles_3d(ax: Any, record: RunRecord) -> None:
    """The bodies (up to the ceiling) and spheres. A body's surfaces carry the gid "avoid
    <its name>": no other obstacle's name may lie on them (``labels.clutter``)."""
    sc = record.scenario
    z_top = sc.limits.altitude[1]
    for body, sensed, name in zip(sc.bodies, sc.sensed, obstacle_names(record)[0], strict=True):
        h = min(body.height, z_top)
        alpha = 0.35 if sensed else 0.15
        if isinstance(body, Cylinder):
            drawn = _cylinder_3d(ax, body, h, alpha)
        else:
            drawn = _box_3d(ax, body, h, alpha)
        for artist in drawn:
            artist.set_gid(f"avoid {name}")
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


def _path_3d(ax: Any, p: np.ndarray, goal: np.ndarray, color: str, dash: Any) -> None:
    ax.plot(p[:, 0], p[:, 1], p[:, 2], color=color, linestyle=dash)
    for point, marker, size in ((p[0], "o", 16), (goal, "x", 26)):
        ax.scatter(*point, color=color, marker=marker, s=size, depthshade=False)


def _zones_3d(ax: Any, record: RunRecord, snaps: list[ZoneSnapshot], colors: list) -> None:
    for k, snap in enumerate(snaps):
        for i, c in zip(snap.agents, snap.positions, strict=True):
            _sphere_3d(
                ax,
                c,
                float(record.scenario.r_pz[i]),
                color=colors[i],
                linewidth=0.5,
                alpha=0.55,
                linestyle=zone_dash(k),
            )
            ax.scatter(*c, color=colors[i], edgecolor="k", s=30, depthshade=False, zorder=5)


def _label_obstacles_3d(ax: Any, record: RunRecord) -> None:
    """Each obstacle's name by its top, clear of the paths, the other names and the other
    bodies (projected as last drawn; the figure's layout settled)."""
    sc = record.scenario
    if not 0 < len(sc.bodies) + len(sc.spheres) <= NAMED_3D:
        return
    z_top = sc.limits.altitude[1]
    bodies, spheres = obstacle_names(record)
    tops = [(b.center[0], b.center[1], min(b.height, z_top)) for b in sc.bodies]
    tops += [(s.center[0], s.center[1], s.center[2] + s.radius) for s in sc.spheres]
    xs, ys, _ = proj3d.proj_transform(*np.array(tops, dtype=float).T, ax.get_proj())
    anchors = list(zip(xs, ys, strict=True))
    for k, name in enumerate(bodies + spheres):
        rivals = anchors[:k] + anchors[k + 1 :]
        # by the top, clear of paths, names and other obstacles, on a light ground where it
        # lies over its own; left to the top view when it has no such place
        place_label(
            ax,
            name,
            anchors[k],
            base=2.0,
            prefer=math.pi / 2,
            rivals=rivals,
            reach=NAME_REACH,
            optional=True,
            fontsize=8,
            color="0.15",
            bbox=NAME_GROUND,
        )


def _keys_around_box(
    fig: Figure,
    ax: Any,
    agents: tuple[list, list[str]],
    key: tuple[list, list[str]],
    *,
    title: str,
    gap: float = 0.015,
) -> None:
    """Title above the projected 3D box, the agents at its right, the key below it: placed from
    the drawn box, so cropping to the content leaves no empty margin."""
    fig.draw_without_rendering()
    (x0, y0), (x1, y1) = fig.transFigure.inverted().transform(box_3d_extent(ax).get_points())
    fig.text((x0 + x1) / 2, y1 + gap, title, ha="center", va="bottom", fontsize=11)
    if agents[0]:
        fig.legend(
            *agents,
            loc="upper left",
            bbox_to_anchor=(x1 + gap, y1),
            frameon=False,
            borderaxespad=0.0,
        )
    if key[0]:
        fig.legend(
            *key,
            loc="upper center",
            bbox_to_anchor=((x0 + x1) / 2, y0 - gap),
            ncols=min(3, len(key[0])),
            frameon=False,
            borderaxespad=0.0,
        )


def _set_box(ax: Any, lo: np.ndarray, hi: np.ndarray) -> None:
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
    ax.tick_params(labelsize=9, pad=0)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5 if axis is not ax.zaxis else 4))


def _swarm_paths_3d(ax: Any, record: RunRecord) -> tuple[list, tuple[list, list[str]]]:
    """A swarm's named sample of paths over every vehicle's start (small grey dots); the
    colour of every agent (grey but the sample's) and the key's entries."""
    p = record.positions[drawn_indices(record)]
    agents = sample_agents(record, closest_pairs(record))
    ax.scatter(p[0, :, 0], p[0, :, 1], p[0, :, 2], color="0.7", s=1.5, depthshade=False)
    colors: list = ["0.35"] * record.n_agents
    handles: list = []
    for k, i in enumerate(agents):
        colors[i] = PALETTE[k % len(PALETTE)]
        _path_3d(ax, p[:, i], record.scenario.goals[i], colors[i], "-")
        handles.append(Line2D([], [], color=colors[i], linewidth=1.8))
    names = [record.ids[i] for i in agents]
    names[0] += f"\n(a sample of {len(agents)} paths)"
    handles.append(marker_handle("o", 2.5, color="0.7"))
    names.append(f"start of each of\nthe {record.n_agents} vehicles")
    return colors, (handles, names)


@styled
def figure_trajectories_3d(record: RunRecord, *, zones: Zones = DEFAULT_ZONES) -> Figure:
    """3D flight paths with cylinders, boxes and spheres (Figs. 13b, 15b), equal scale on all
    three axes, the box hugging the scene, the keys placed around the projected box; a swarm
    (more than LEGEND_MAX_AGENTS vehicles) as a named sample of paths."""
    sc = record.scenario
    snaps = zone_snapshots(record, zones)
    lo, hi = _equal_limits(*scene_bounds(record, snaps))
    fig = new_figure((7.0, 5.2), layout=None)
    ax = cast(Axes3D, fig.add_axes((0.0, 0.0, 1.0, 1.0), projection="3d", proj_type="ortho"))
    _obstacles_3d(ax, record)
    if record.n_agents > LEGEND_MAX_AGENTS:
        colors, agents = _swarm_paths_3d(ax, record)
    else:
        styles = agent_styles(record.n_agents)
        colors = [c for c, _ in styles]
        for i, (color, dash) in enumerate(styles):
            _path_3d(ax, record.positions[:, i], sc.goals[i], color, dash)
        agents = agent_handles(record)
    _zones_3d(ax, record, snaps, colors)
    _set_box(ax, lo, hi)
    named = "named as in the summary\nwhere the name fits"
    key = key_handles(record, snaps, prisms=False, named=named)
    title = f"{sc.name} ({record.formulation} / {record.solver})"
    _keys_around_box(fig, ax, agents, key, title=title)
    settle(fig)
    _label_obstacles_3d(ax, record)
    return fig
