"""What every figure shares: the print style, the colour-blind-safe palette, the Agg canvas,
and writing a figure to PNG, PDF or SVG cropped to what is drawn."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, ParamSpec, TypeVar, cast

import numpy as np

from vo3d_opt.extras import needs

with needs("sim", "plotting"):
    from matplotlib import colormaps, rc_context
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.transforms import Bbox
    from mpl_toolkits.mplot3d import proj3d

#: File formats every figure can be written in (the file's suffix chooses).
FORMATS = ("png", "pdf", "svg")
#: Resolution (dots per inch) of PNG figures; PDF and SVG are vector graphics.
DEFAULT_DPI = 150
#: Up to this many agents every vehicle is drawn and named; beyond, a run is drawn as a swarm
#: (occupancy, the closest pairs, a named sample of paths, distance bands).
LEGEND_MAX_AGENTS = 12

#: Paul Tol's "muted" qualitative palette: nine colours told apart under the common colour
#: vision deficiencies and in greyscale print by their lightness (https://personal.sron.nl/~pault/).
PALETTE = (
    "#332288",
    "#CC6677",
    "#117733",
    "#DDCC77",
    "#88CCEE",
    "#882255",
    "#44AA99",
    "#999933",
    "#AA4499",
)
#: Line patterns, cycled once the palette's colours are used up (and for curves that must stay
#: visible when they lie on top of one another).
DASHES: tuple[Any, ...] = (
    "-",
    (0, (5, 2)),
    (0, (1, 1.5)),
    (0, (6, 2, 1, 2)),
    (0, (3, 1, 1, 1, 1, 1)),
)
OBSTACLE_GREY, UNSENSED_GREY, PRISM_GREY = "0.55", "0.82", "0.25"
#: Reference lines (r_pz, prism margins) and the closest-approach marker.
REFERENCE = "black"
#: Occupancy (a swarm's density over the top view): white to mid grey, so that the palette's
#: colours, black marks and text stay legible over it, in colour and in greyscale.
DENSITY_CMAP = ListedColormap(colormaps["Greys"](np.linspace(0.04, 0.62, 256)), "occupancy")

#: Sizes for print: a 7-inch figure shrunk to a 3.5-inch column keeps 5-pt text at least.
STYLE: dict[str, Any] = {
    "font.size": 10.0,
    "axes.titlesize": 11.0,
    "axes.labelsize": 10.0,
    "legend.fontsize": 9.0,
    "xtick.labelsize": 9.0,
    "ytick.labelsize": 9.0,
    "lines.linewidth": 1.5,
    "legend.borderpad": 0.1,  # no frame: a pad would only widen the crop
    "axes.linewidth": 0.8,
    "grid.linewidth": 0.5,
    "grid.alpha": 0.6,
}

P = ParamSpec("P")
R = TypeVar("R")


def styled(build: Callable[P, R]) -> Callable[P, R]:
    """Build a figure under :data:`STYLE` (matplotlib reads its rc settings as artists are
    made, so the figure keeps them, whatever the caller's defaults)."""

    @functools.wraps(build)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with rc_context(cast(Any, STYLE)):
            return build(*args, **kwargs)

    return wrapper


def agent_styles(n: int) -> list[tuple[str, Any]]:
    """(colour, line pattern) of each of n agents: the palette's colours solid, then again
    dashed, and so on, so no two of the first 45 agents look alike."""
    k = len(PALETTE)
    return [(PALETTE[i % k], DASHES[(i // k) % len(DASHES)]) for i in range(n)]


def agent_colors(n: int) -> list[str]:
    """One colour per agent (:func:`agent_styles`' colours)."""
    return [c for c, _ in agent_styles(n)]


def new_figure(
    figsize: tuple[float, float], *, layout: Literal["constrained"] | None = "constrained"
) -> Figure:
    """A figure on its own Agg canvas (no pyplot, no global backend)."""
    fig = Figure(figsize=figsize, layout=layout)
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


def box_3d_extent(ax: Any) -> Bbox:
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


def settle(fig: Figure) -> None:
    """Lay the figure out once and keep that layout: what is placed after (labels placed by
    their drawn extents) must not move when the figure is drawn again."""
    fig.draw_without_rendering()
    fig.set_layout_engine("none")


def content_bbox(fig: Figure, pad: float = 0.06) -> Bbox:
    """What is drawn, in inches, plus ``pad``. Unlike ``bbox_inches="tight"``, a 3D axes counts
    by its box, ticks and labels, not by its whole rectangle, which the projected box fills only
    in part: cropping to it leaves no wide empty margins."""
    settle(fig)
    renderer = cast(FigureCanvasAgg, fig.canvas).get_renderer()
    boxes: list[Bbox | None] = [a.get_window_extent(renderer) for a in [*fig.legends, *fig.texts]]
    for ax in fig.axes:
        if ax.name != "3d":
            boxes.append(ax.get_tightbbox(renderer))
            continue
        boxes.append(box_3d_extent(ax))
        boxes += [a.get_tightbbox(renderer) for a in (ax.title, ax.get_legend()) if a is not None]
        boxes += [t.get_window_extent(renderer) for t in ax.texts if t.get_visible()]
    box = Bbox.union([b for b in boxes if b is not None and b.width > 0])
    return box.transformed(fig.dpi_scale_trans.inverted()).padded(pad)


def save_figure(fig: Figure, path: str | Path, dpi: int = DEFAULT_DPI) -> Path:
    """Write ``fig`` in the format of the path's suffix, cropped to what is drawn."""
    fmt = figure_format(path)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Text stays text in SVG and TrueType in PDF (journals reject Type 3 fonts); no dates, so a
    # file is reproducible.
    with rc_context({"svg.fonttype": "none", "pdf.fonttype": 42, "svg.hashsalt": "vo3d"}):
        fig.savefig(
            path,
            dpi=check_dpi(dpi),
            bbox_inches=content_bbox(fig),
            metadata={"pdf": {"CreationDate": None}, "svg": {"Date": None}}.get(fmt),
        )
    return path
