"""A replay of a run as an animated GIF: the vehicles moving with their protected spheres, over
the obstacles, in plan (x-y) above a side view (x-z), both to scale and sharing the x axis.

Each frame draws the obstacles as the planner and the geometry see them at that moment: in plan
each protected prism C_pz is the square of side L_pz turned to face the nearest vehicle (section
4.1); in the side view an obstacle is cut at the depth of a vehicle abreast of it, so that no
vehicle beside a pillar looks inside it (``vo3d_opt.figures.sections``).

Frame rule: every sample when the run has at most ``max_frames`` (150) of them, otherwise
``max_frames`` samples evenly spaced in time, the first and last always included; played at
``fps`` (10) frames per second, so a replay lasts at most 15 s whatever the run's length. The
GIF is drawn at a fixed size (about 700 px wide at the default 80 dpi); should it still come out
above ``max_bytes`` (8 MB), it is drawn again with proportionally fewer frames, so a 1,000-step
run of many vehicles stays small. With more than 12 vehicles each trails only its last 10 s of
path and the faint paths ahead are left out, so the picture stays readable. Written with
matplotlib's ``PillowWriter`` (pillow comes with matplotlib); :func:`write_frame` writes one
frame as a PNG.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.figures.keys import key_handles
from vo3d_opt.figures.scene import obstacle_names, prism_square, scene_bounds
from vo3d_opt.figures.sections import SideSection, side_sections
from vo3d_opt.figures.style import (
    DEFAULT_DPI,
    LEGEND_MAX_AGENTS,
    OBSTACLE_GREY,
    PRISM_GREY,
    UNSENSED_GREY,
    agent_styles,
    check_dpi,
    styled,
)
from vo3d_opt.figures.topview import draw_obstacles_2d, label_obstacles
from vo3d_opt.sim.metrics import closest_obstacle_approach, closest_vehicle_approach
from vo3d_opt.sim.record import RunRecord

with needs("sim", "animation"):  # matplotlib brings Pillow
    from matplotlib.animation import PillowWriter
    from matplotlib.artist import Artist
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import EllipseCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch, Polygon, Rectangle
    from PIL import Image

MAX_FRAMES = 150
FPS = 10
GIF_DPI = 80
MAX_BYTES = 8_000_000
#: With more than LEGEND_MAX_AGENTS vehicles, each trails only its last seconds of path.
TRAIL_SECONDS = 10.0
#: The key's words for what the replay draws of the obstacles.
PRISM_NOW = "protected prism C_pz: square of\nside L_pz, turned to face the\nnearest vehicle"
SIDE_CUT = (
    "side view: each obstacle cut\n"
    "at the depth (y) of a vehicle\n"
    "abreast of it; never drawn\n"
    "over a vehicle beside it"
)


def frame_indices(n_samples: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """Sample indices shown: all of them up to ``max_frames``, else ``max_frames`` evenly
    spaced ones with the first and the last."""
    if max_frames < 2:
        raise ValueError(f"max_frames: {max_frames!r} must be at least 2")
    if n_samples <= max_frames:
        return np.arange(n_samples)
    return np.linspace(0, n_samples - 1, max_frames).round().astype(int)


@dataclass
class Replay:
    """The replay's figure and what each frame moves."""

    fig: Figure
    title: Any
    view_top: float  # the side view's upper edge (m)
    dots: list[Any] = field(default_factory=list)  # plan, side
    zones: list[EllipseCollection] = field(default_factory=list)
    trails: list[list[Line2D]] = field(default_factory=list)
    prisms: dict[int, Polygon] = field(default_factory=dict)  # plan, by body
    cuts: dict[tuple[str, str], Patch] = field(default_factory=dict)  # side, by (kind, name)

    def moving(self) -> list[Artist]:
        """Everything a frame redraws, in drawing order (obstacles under the vehicles)."""
        return [
            *self.cuts.values(),
            *self.prisms.values(),
            *(line for panel in self.trails for line in panel),
            *self.zones,
            *self.dots,
            self.title,
        ]


def _zones(ax: Any, record: RunRecord, offsets: np.ndarray, colors: list) -> EllipseCollection:
    d = 2.0 * record.scenario.r_pz
    zones = EllipseCollection(
        d,
        d,
        np.zeros_like(d),
        units="xy",
        offsets=offsets,
        offset_transform=ax.transData,
        facecolors="none",
        edgecolors=colors,
        linewidths=0.9,
        linestyles="--",
    )
    ax.add_collection(zones)
    return zones


def _cut_patches(ax: Any, record: RunRecord) -> dict[tuple[str, str], Patch]:
    """One hidden patch per obstacle part the side view may draw, shaped by each frame."""
    sc = record.scenario
    bodies, spheres = obstacle_names(record)
    out: dict[tuple[str, str], Patch] = {}
    for name, sensed in zip(bodies, sc.sensed, strict=True):
        fc = OBSTACLE_GREY if sensed else UNSENSED_GREY
        out["body", name] = Rectangle((0, 0), 0, 0, facecolor=fc, edgecolor="0.3", linewidth=0.6)
        if sensed:
            out["prism", name] = Rectangle(
                (0, 0), 0, 0, fill=False, linestyle="--", edgecolor=PRISM_GREY, linewidth=0.9
            )
    for s, name in zip(sc.spheres, spheres, strict=True):
        out["sphere", name] = Circle(
            (0, 0), 0, fill=False, edgecolor="0.35", linestyle="-" if s.physical else ":"
        )
    for patch in out.values():
        patch.set_visible(False)
        ax.add_patch(patch)
    return out


@dataclass(frozen=True)
class _Layout:
    """The replay's figure: plan above side view, to scale; the view's corners (m) and where
    the legend's upper left corner goes (figure fraction)."""

    fig: Figure
    plan: Any
    side: Any
    lo: np.ndarray
    hi: np.ndarray
    corner: tuple[float, float]


def _layout(record: RunRecord) -> _Layout:
    sc = record.scenario
    lo, hi = scene_bounds(record)
    r = float(sc.r_pz.max())
    lo, hi = lo - r, hi + r  # room for the spheres at the edges
    lo[2] = max(lo[2], min(0.0, sc.limits.altitude[0]))
    x_span, y_span, z_span = hi - lo
    # Axes to scale: about 5.5 in wide, shrunk so that plan and elevation fit in 7 in of height.
    width = min(5.5, 7.0 * x_span / (y_span + z_span))
    left, right, bottom, top_, gap = 0.8, 2.9, 0.55, 0.4, 0.3  # margins, in
    w, h = left + width + right, bottom + width * (y_span + z_span) / x_span + gap + top_
    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    plan, side = fig.subplots(2, 1, sharex=True, height_ratios=[y_span, z_span])
    fig.subplots_adjust(
        left=left / w,
        right=(left + width) / w,
        bottom=bottom / h,
        top=1 - top_ / h,
        hspace=2 * gap / (h - bottom - top_ - gap),
    )
    return _Layout(fig, plan, side, lo, hi, ((left + width + 0.1) / w, 1 - top_ / h))


def _legend(replay: Replay, record: RunRecord, corner: tuple[float, float]) -> None:
    handles, labels = key_handles(record, [], prisms=False)
    if record.scenario.sensed.any():
        handles.append(Line2D([], [], color=PRISM_GREY, linestyle="--", linewidth=1.0))
        labels.append(PRISM_NOW)
    handles.append(
        Line2D(
            [],
            [],
            marker="o",
            markersize=10,
            markerfacecolor="none",
            markeredgecolor="0.2",
            linestyle="none",
        )
    )
    labels.append("protected zone r_pz")
    handles.append(Line2D([], [], color="0.3", linewidth=1.2))
    if record.n_agents <= LEGEND_MAX_AGENTS:
        handles.append(Line2D([], [], color="0.3", linewidth=0.6, alpha=0.3))
        labels += ["path flown", "path ahead"]
    else:
        labels.append(f"path of the last {TRAIL_SECONDS:g} s")
    if record.scenario.bodies or record.scenario.spheres:
        handles.append(Line2D([], [], linestyle="none"))
        labels.append(SIDE_CUT)
    if record.n_agents <= LEGEND_MAX_AGENTS:
        styles = agent_styles(record.n_agents)
        handles = [
            Line2D([], [], color=c, linestyle=ls, linewidth=1.6) for c, ls in styles
        ] + handles
        labels = list(record.ids) + labels
    replay.fig.legend(
        handles,
        labels,
        loc="upper left",
        bbox_to_anchor=corner,
        fontsize=8.5,
        frameon=False,
        borderaxespad=0.0,
    )


def _prism_squares(plan: Any, record: RunRecord) -> dict[int, Polygon]:
    """A dashed square per sensed body's protected prism, turned by each frame."""
    sc = record.scenario
    out = {}
    for k, (body, sensed) in enumerate(zip(sc.bodies, sc.sensed, strict=True)):
        if sensed:
            out[k] = Polygon(
                prism_square(body, body.center),
                closed=True,
                fill=False,
                linestyle="--",
                edgecolor=PRISM_GREY,
                linewidth=0.9,
            )
            plan.add_patch(out[k])
    return out


def _vehicles(replay: Replay, layout: _Layout, record: RunRecord) -> None:
    """In each panel: the paths ahead (faint, up to LEGEND_MAX_AGENTS vehicles), and the
    trails, protected spheres and dots each frame moves."""
    p = record.positions
    few = record.n_agents <= LEGEND_MAX_AGENTS
    styles = agent_styles(record.n_agents)
    if not few:  # no vehicle is named: solid trails, cheaper to draw by the thousand
        styles = [(c, "-") for c, _ in styles]
    colors = [c for c, _ in styles]
    for ax, (a, b) in ((layout.plan, (0, 1)), (layout.side, (0, 2))):
        for i in range(record.n_agents if few else 0):
            ax.plot(p[:, i, a], p[:, i, b], color=colors[i], linewidth=0.6, alpha=0.3)
        replay.trails.append(
            [ax.plot([], [], color=c, linestyle=ls, linewidth=1.2)[0] for c, ls in styles]
        )
        replay.zones.append(_zones(ax, record, p[0][:, [a, b]], colors))
        replay.dots.append(ax.scatter(p[0, :, a], p[0, :, b], c=colors, s=14, zorder=5))
        ax.set_aspect("equal", adjustable="box")
        ax.grid(True)


@styled
def build_replay(record: RunRecord) -> Replay:
    """The figure with everything static drawn, and the artists each frame moves."""
    sc = record.scenario
    layout = _layout(record)
    plan, lo, hi = layout.plan, layout.lo, layout.hi
    colors = agent_styles(record.n_agents)
    draw_obstacles_2d(plan, record, prisms=False)
    plan.scatter(sc.starts[:, 0], sc.starts[:, 1], c=[c for c, _ in colors], marker="o", s=9)
    plan.scatter(sc.goals[:, 0], sc.goals[:, 1], c=[c for c, _ in colors], marker="x", s=16)
    # the longest title, so that the layout leaves room for every frame's
    title = layout.fig.suptitle(_title(record, len(record.times) - 1), fontsize=11)
    replay = Replay(layout.fig, title, view_top=float(hi[2]))
    replay.cuts = _cut_patches(layout.side, record)
    replay.prisms = _prism_squares(plan, record)
    _vehicles(replay, layout, record)
    plan.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), ylabel="y (m)")
    layout.side.set(ylim=(lo[2], hi[2]), xlabel="x (m)", ylabel="z (m)")
    _legend(replay, record, layout.corner)
    layout.fig.draw_without_rendering()  # the names are placed from the drawn layout
    label_obstacles(plan, record, turning=True)
    return replay


def _shape(patch: Patch, cut: SideSection) -> None:
    if isinstance(patch, Circle):
        patch.set_center((cut.cx, cut.cz))
        patch.set_radius(cut.radius)
    elif isinstance(patch, Rectangle):
        patch.set_bounds(cut.x0, cut.z0, cut.x1 - cut.x0, cut.z1 - cut.z0)
    patch.set_visible(True)


def show_frame(replay: Replay, record: RunRecord, k: int) -> list[SideSection]:
    """Move everything to sample k; the side view's sections drawn."""
    p = record.positions
    few = record.n_agents <= LEGEND_MAX_AGENTS
    trail = int(round(TRAIL_SECONDS / record.dt))  # with many vehicles, only their recent path
    first = 0 if few else max(0, k - trail)
    for panel, (a, b) in enumerate(((0, 1), (0, 2))):
        replay.dots[panel].set_offsets(p[k][:, [a, b]])
        replay.zones[panel].set_offsets(p[k][:, [a, b]])
        for i, line in enumerate(replay.trails[panel]):
            line.set_data(p[first : k + 1, i, a], p[first : k + 1, i, b])
    bodies = record.scenario.bodies
    for j, square in replay.prisms.items():
        near = int(np.argmin(np.linalg.norm(p[k][:, :2] - bodies[j].center, axis=1)))
        square.set_xy(prism_square(bodies[j], p[k][near]))
    cuts = side_sections(record, np.asarray(p[k]), top=replay.view_top)
    for patch in replay.cuts.values():
        patch.set_visible(False)
    for cut in cuts:
        _shape(replay.cuts[cut.kind, cut.name], cut)
    replay.title.set_text(_title(record, k))
    return cuts


def write_animation(
    record: RunRecord,
    path: str | Path,
    *,
    max_frames: int = MAX_FRAMES,
    fps: int = FPS,
    dpi: int = GIF_DPI,
    max_bytes: int = MAX_BYTES,
) -> Path:
    """Write the replay GIF to ``path`` (see the module's frame and size rule); the path."""
    path = Path(path)
    if path.suffix.lower() != ".gif":
        raise ValueError(f"path: {str(path)!r} must end in .gif")
    check_dpi(dpi)
    path.parent.mkdir(parents=True, exist_ok=True)
    frames = frame_indices(len(record.times), max_frames)
    while True:
        _render(record, path, frames, fps=fps, dpi=dpi)
        size = path.stat().st_size
        if size <= max_bytes or len(frames) <= 10:
            return path
        fewer = max(10, int(len(frames) * max_bytes / size * 0.9))
        frames = frame_indices(len(record.times), fewer)


def frame_at(record: RunRecord, time: float | None) -> int:
    """The sample shown at ``time`` (s; the nearest), or at the run's closest approach (between
    vehicles, else to an obstacle; else its middle) when None."""
    if time is None:
        found = closest_vehicle_approach(record) or closest_obstacle_approach(record)
        time = found.time if found is not None else float(record.times[-1]) / 2.0
    if not math.isfinite(time):
        raise ValueError(f"time: {time!r} must be finite")
    return int(np.argmin(np.abs(record.times - time)))


def write_frame(
    record: RunRecord, path: str | Path, *, time: float | None = None, dpi: int = DEFAULT_DPI
) -> Path:
    """One frame of the replay as a PNG (:func:`frame_at` chooses it); the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"path: {str(path)!r} must end in .png")
    check_dpi(dpi)
    replay = build_replay(record)
    show_frame(replay, record, frame_at(record, time))
    path.parent.mkdir(parents=True, exist_ok=True)
    replay.fig.savefig(path, dpi=dpi)
    return path


def _title(record: RunRecord, k: int) -> str:
    return f"{record.scenario.name}   t = {record.times[k]:.1f} s"


class _BlitPillowWriter(PillowWriter):
    """matplotlib's PillowWriter taking each frame from the canvas as it stands (the caller
    redraws only what moves over a saved background: a full redraw costs ten times more), in a
    palette of at most 128 colours fixed by the first frame and no dithering, which keeps the
    GIF small."""

    _frames: list[Image.Image]  # PillowWriter's, filled by grab_frame, written by finish
    _palette: Image.Image

    def grab_frame(self, **savefig_kwargs) -> None:
        canvas = cast(FigureCanvasAgg, self.fig.canvas)
        rgb = Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3])
        if not self._frames:
            self._palette = rgb.quantize(colors=128, method=Image.Quantize.MEDIANCUT)
        self._frames.append(rgb.quantize(palette=self._palette, dither=Image.Dither.NONE))


def _render(record: RunRecord, path: Path, frames: np.ndarray, *, fps: int, dpi: int) -> None:
    replay = build_replay(record)
    fig = replay.fig
    fig.set_dpi(dpi)
    artists = replay.moving()
    for artist in artists:
        artist.set_animated(True)
    canvas = cast(FigureCanvasAgg, fig.canvas)
    writer = _BlitPillowWriter(fps=fps)
    with writer.saving(fig, path, dpi):
        canvas.draw()
        background = canvas.copy_from_bbox(fig.bbox)
        for k in frames:
            canvas.restore_region(background)
            show_frame(replay, record, int(k))
            for artist in artists:
                if artist.get_visible():
                    fig.draw_artist(artist)
            writer.grab_frame()
