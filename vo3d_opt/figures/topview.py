"""The top view (the paper's Figs. 13a, 15a, 19a): paths over the obstacles, each obstacle named
as the summary names it, its protected prism drawn as the square the planner turns to face the
vehicle, and the vehicles' protected spheres at chosen moments."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.sim.record import RunRecord
from vo3d_opt.types import Cylinder

from .keys import agent_key, key_handles, zone_dash
from .labels import clutter, place_label
from .scene import (
    DEFAULT_ZONES,
    Zones,
    ZoneSnapshot,
    box_corners,
    nearest_passes,
    prism_square,
    scene_bounds,
    xy,
    zone_snapshots,
)
from .style import (
    OBSTACLE_GREY,
    PRISM_GREY,
    UNSENSED_GREY,
    agent_styles,
    new_figure,
    settle,
    styled,
)

with needs("sim", "plotting"):
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon

#: Font size (points) of the obstacles' names.
NAME_SIZE = 8.0


def draw_obstacles_2d(ax: Axes, record: RunRecord, *, prisms: bool = True) -> None:
    """Obstacles filled (lighter when not sensed); the protected prism C_pz of each sensed one
    dashed, as the square (side L_pz) the planner turned to face the vehicle that passed
    nearest, a dotted line to where that vehicle was (``prisms``); spheres as circles (dotted:
    not physical)."""
    sc = record.scenario
    passes = nearest_passes(record) if prisms else [None] * len(sc.bodies)
    for body, sensed, toward in zip(sc.bodies, sc.sensed, passes, strict=True):
        fc = OBSTACLE_GREY if sensed else UNSENSED_GREY
        if isinstance(body, Cylinder):
            ax.add_patch(Circle(xy(body.center), body.radius, facecolor=fc, edgecolor="0.3"))
        else:
            ax.add_patch(Polygon(box_corners(body), closed=True, facecolor=fc, edgecolor="0.3"))
        if sensed and toward is not None:
            square = prism_square(body, toward)
            ax.add_patch(
                Polygon(square, closed=True, fill=False, linestyle="--", edgecolor=PRISM_GREY)
            )
            ax.patches[-1].set_gid("prism")
            ax.plot(*np.array([body.center, toward[:2]]).T, ":", color=PRISM_GREY, linewidth=0.9)
    for s in sc.spheres:
        ax.add_patch(
            Circle(
                xy(s.center),
                s.radius,
                fill=False,
                edgecolor="0.35",
                linestyle="-" if s.physical else ":",
            )
        )


def points_per_metre(ax: Axes) -> float:
    """How many points (1/72 in) one metre of the (equal-aspect) data spans, as drawn."""
    a, b = ax.transData.transform([(0.0, 0.0), (1.0, 0.0)])
    return float(abs(b[0] - a[0]) * 72.0 / ax.figure.dpi)


@dataclass(frozen=True)
class Place:
    """Where the top view names obstacles: the ``centre`` (x, y) of the ones standing there,
    how far they ``reach`` from it (m), and their ``name``."""

    centre: tuple[float, float]
    reach: float
    name: str


@dataclass(frozen=True)
class _Shape:
    centre: tuple[float, float]
    reach: float
    kind: str  # "obstacles" or "spheres"
    index: int


def _shapes(record: RunRecord, turning: bool) -> list[_Shape]:
    sc = record.scenario
    out = []
    for k, (b, sensed) in enumerate(zip(sc.bodies, sc.sensed, strict=True)):
        reach = b.side / math.sqrt(2.0) if turning and sensed else b.footprint_extent() / 2.0
        out.append(_Shape(xy(b.center), reach, "obstacles", k))
    out += [_Shape(xy(s.center), float(s.radius), "spheres", k) for k, s in enumerate(sc.spheres)]
    return out


def obstacle_places(record: RunRecord, *, turning: bool = False) -> list[Place]:
    """Each place the top view names: obstacles stacked over one point (a cylinder and the
    spheres standing for it) share one name of a line per kind, e.g. "obstacles[0]" above
    "spheres[0, 1, 2]". ``turning``: a sensed body reaches as far as its prism's corners
    turned any way (a replay turns them frame by frame)."""
    groups: dict[tuple[float, float], list[_Shape]] = {}
    for shape in _shapes(record, turning):
        groups.setdefault((round(shape.centre[0], 6), round(shape.centre[1], 6)), []).append(shape)
    out = []
    for members in groups.values():
        lines = []
        for kind in ("obstacles", "spheres"):
            ks = [str(m.index) for m in members if m.kind == kind]
            if ks:
                lines.append(f"{kind}[{', '.join(ks)}]")
        reach = max(m.reach for m in members)
        out.append(Place(members[0].centre, reach, "\n".join(lines)))
    return out


def label_obstacles(ax: Axes, record: RunRecord, *, turning: bool = False) -> list[Any]:
    """Every obstacle's name (:func:`obstacle_places`, ``turning``) beside it, clear of paths,
    shapes and the other names; the figure's layout must be settled. Returns the labels."""
    scale = points_per_metre(ax)
    places = obstacle_places(record, turning=turning)
    around = clutter(ax, ax.figure.canvas.get_renderer())  # type: ignore[attr-defined]
    centres = [p.centre for p in places]
    out = []
    for k, place in enumerate(places):
        rivals = centres[:k] + centres[k + 1 :]
        out.append(
            place_label(
                ax,
                place.name,
                place.centre,
                base=place.reach * scale,
                prefer=math.pi / 2,
                rivals=rivals,
                around=around,
                fontsize=NAME_SIZE,
                color="0.15",
                linespacing=1.1,
            )
        )
    return out


def draw_zones_2d(ax: Axes, record: RunRecord, snaps: list[ZoneSnapshot], colors: list) -> None:
    """The protected spheres (radius r_pz) of each snapshot's vehicles, seen from above."""
    for k, snap in enumerate(snaps):
        for i, c in zip(snap.agents, snap.positions, strict=True):
            ax.add_patch(
                Circle(
                    xy(c),
                    float(record.scenario.r_pz[i]),
                    fill=False,
                    edgecolor=colors[i],
                    linewidth=1.0,
                    linestyle=zone_dash(k),
                )
            )
            ax.plot(*c[:2], "o", color=colors[i], markeredgecolor="k", markersize=6)


def map_size(
    record: RunRecord, snaps: list[ZoneSnapshot], *, width: float, extra: tuple[float, float]
) -> tuple[float, float]:
    """A figure size (in) whose map, ``width`` wide at the scene's aspect (its height kept
    between 2.4 and 6 in), leaves no empty band: ``extra`` (w, h) in for keys and titles."""
    lo, hi = scene_bounds(record, snaps)
    height = width * max(hi[1] - lo[1], 1e-3) / max(hi[0] - lo[0], 1e-3)
    if height > 6.0:
        width, height = width * 6.0 / height, 6.0
    return width + extra[0], max(height, 2.4) + extra[1]


def frame_map(ax: Axes, lo: np.ndarray, hi: np.ndarray) -> None:
    """A map of [lo, hi] (x, y) at equal scale, axis labels with units, a light grid."""
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True)


def frame_top_view(ax: Axes, record: RunRecord, snaps: list[ZoneSnapshot]) -> None:
    """:func:`frame_map` of the scene with a small pad."""
    lo, hi = scene_bounds(record, snaps)
    pad = 0.03 * max(hi[0] - lo[0], hi[1] - lo[1], 1e-3)
    frame_map(ax, lo[:2] - pad, hi[:2] + pad)


@styled
def figure_agents_top_view(record: RunRecord, *, zones: Zones = DEFAULT_ZONES) -> Figure:
    """Top view (Figs. 13a, 15a, 19a) of a run of a few agents: every path, start and goal in
    its agent's colour and pattern over the named obstacles and their protected prisms."""
    sc = record.scenario
    snaps = zone_snapshots(record, zones)
    handles, labels = key_handles(record, snaps, prisms=True)
    lines = sum(label.count("\n") + 1 for label in labels)
    fig = new_figure(map_size(record, snaps, width=5.2, extra=(1.6, 0.9 + 0.11 * lines)))
    ax = fig.add_subplot()
    styles = agent_styles(record.n_agents)
    colors = [c for c, _ in styles]
    draw_obstacles_2d(ax, record)
    p = record.positions
    for i, (color, dash) in enumerate(styles):
        ax.plot(p[:, i, 0], p[:, i, 1], color=color, linestyle=dash)
        ax.plot(*p[0, i, :2], "o", color=color, markersize=4.5)
        ax.plot(*sc.goals[i, :2], "x", color=color, markersize=7, markeredgewidth=1.5)
    draw_zones_2d(ax, record, snaps, colors)
    frame_top_view(ax, record, snaps)
    ax.set_title(f"{sc.name}: top view")
    agent_key(fig, ax, record, handles=handles, labels=labels)
    settle(fig)
    label_obstacles(ax, record)
    return fig
