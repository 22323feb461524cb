"""Legend entries: the agents by name, and a key for every marker, outline and area drawn, so
that nothing on a figure goes unexplained."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from vo3d_opt.extras import needs
from vo3d_opt.sim.record import RunRecord

from .scene import ZoneSnapshot
from .style import OBSTACLE_GREY, PRISM_GREY, UNSENSED_GREY, agent_styles

with needs("sim", "plotting"):
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

#: Outline of the protected spheres of the k-th snapshot (cycled): tells the times apart.
ZONE_DASHES = [(0, (4, 2)), (0, (1, 1.5)), (0, (6, 2, 1, 2)), (0, (8, 3))]
#: What the drawn protected prism is: the planner's square, turned as it was for one vehicle.
PRISM_LABEL = (
    "protected prism C_pz: square of side L_pz that\n"
    "turns to face each vehicle (paper section 4.1),\n"
    "drawn facing the nearest pass (dotted line)"
)


def zone_dash(k: int) -> tuple:
    return ZONE_DASHES[k % len(ZONE_DASHES)]


def zone_handle(k: int) -> Line2D:
    """A vehicle (dot) and the outline of its protected sphere as the k-th snapshot draws it."""
    return Line2D(
        [],
        [],
        color="0.2",
        linestyle=zone_dash(k),
        linewidth=1.0,
        marker="o",
        markersize=5,
        markerfacecolor="0.5",
        markeredgecolor="k",
    )


def marker_handle(marker: str, size: float = 6.0, **kw: Any) -> Line2D:
    """A key entry of a marker alone (dark grey unless ``color`` is given)."""
    kw = {"color": "0.2", **kw}
    return Line2D([], [], marker=marker, linestyle="none", markersize=size, **kw)


def key_handles(
    record: RunRecord,
    snaps: Sequence[ZoneSnapshot],
    *,
    prisms: bool,
    ends: bool = True,
    named: str = "named as in the summary",
) -> tuple[list, list[str]]:
    """Legend entries explaining the markers and outlines (not the agents): start and goal
    (``ends``), obstacles (``named``: how the figure names them), their protected prisms
    (``prisms``: drawn as the planner turns them), spheres and the protected spheres of
    ``snaps``."""
    sc = record.scenario
    handles: list = []
    labels: list[str] = []
    if ends:
        handles += [marker_handle("o", 5), marker_handle("x", 6)]
        labels += ["start", "goal"]
    if sc.sensed.any():
        handles.append(Patch(facecolor=OBSTACLE_GREY, edgecolor="0.3"))
        labels.append(f"obstacle, {named}")
    if sc.bodies:
        if prisms and sc.sensed.any():
            handles.append(Line2D([], [], color=PRISM_GREY, linestyle="--", linewidth=1.0))
            labels.append(PRISM_LABEL)
        if not sc.sensed.all():
            handles.append(Patch(facecolor=UNSENSED_GREY, edgecolor="0.3"))
            labels.append("obstacle not sensed")
    if sc.spheres:
        handles.append(marker_handle("o", 9, markerfacecolor="none", markeredgecolor="0.35"))
        labels.append("static sphere\n(dotted: not physical)")
    for k, snap in enumerate(snaps):
        handles.append(zone_handle(k))
        labels.append(snap.label)
    return handles, labels


def agent_handles(record: RunRecord) -> tuple[list, list[str]]:
    """One entry per agent: its colour and line pattern, its id."""
    styles = agent_styles(record.n_agents)
    handles = [Line2D([], [], color=c, linestyle=ls, linewidth=1.8) for c, ls in styles]
    return handles, list(record.ids)


def side_legend(ax: Axes, handles: list, labels: list[str], pad: float = 0.02) -> None:
    """A legend at the right of ``ax``, outside it."""
    ax.legend(
        handles,
        labels,
        loc="upper left",
        bbox_to_anchor=(1.0 + pad, 1.0),
        borderaxespad=0.0,
        frameon=False,
    )


def agent_key(fig: Figure, ax: Axes, record: RunRecord, *, handles=None, labels=None) -> None:
    """The agents named by a legend at the right of ``ax``; the key (``handles``, ``labels``)
    below the figure, in two columns."""
    side_legend(ax, *agent_handles(record))
    if handles:
        fig.legend(
            list(handles), list(labels or []), loc="outside lower center", ncols=2, frameon=False
        )
