"""A replay of a run as an animated GIF: the vehicles moving with their protected spheres, over
the obstacles, in plan (x-y) above elevation (x-z), both to scale and sharing the x axis.

Frame rule: every sample when the run has at most ``max_frames`` (150) of them, otherwise
``max_frames`` samples evenly spaced in time, the first and last always included; played at
``fps`` (10) frames per second, so a replay lasts at most 15 s whatever the run's length. The
GIF is drawn at a fixed size (about 700 px wide at the default 80 dpi); should it still come out
above ``max_bytes`` (8 MB), it is drawn again with proportionally fewer frames, so a 1,000-step
run of many vehicles stays small. With more than 12 vehicles each trails only its last 10 s of
path and the faint paths ahead are left out, so the picture stays readable. Written with
matplotlib's ``PillowWriter`` (pillow comes with matplotlib).
"""

from __future__ import annotations

from pathlib import Path
from typing import cast

import numpy as np
from matplotlib.animation import PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import EllipseCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Rectangle
from PIL import Image

from vo3d_opt.plots import (
    LEGEND_MAX_AGENTS,
    OBSTACLE_GREY,
    PRISM_GREY,
    agent_colors,
    box_corners,
    check_dpi,
    draw_obstacles_2d,
    key_handles,
    scene_bounds,
)
from vo3d_opt.sim.simulator import RunRecord
from vo3d_opt.types import Cylinder

MAX_FRAMES = 150
FPS = 10
GIF_DPI = 80
MAX_BYTES = 8_000_000
#: With more than LEGEND_MAX_AGENTS vehicles, each trails only its last seconds of path.
TRAIL_SECONDS = 10.0


def frame_indices(n_samples: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """Sample indices shown: all of them up to ``max_frames``, else ``max_frames`` evenly
    spaced ones with the first and the last."""
    if max_frames < 2:
        raise ValueError(f"max_frames: {max_frames!r} must be at least 2")
    if n_samples <= max_frames:
        return np.arange(n_samples)
    return np.linspace(0, n_samples - 1, max_frames).round().astype(int)


def _elevation_obstacles(ax, record: RunRecord) -> None:
    """Obstacles seen from the side (-y): bodies filled, protected prisms dashed."""
    sc = record.scenario
    z_top = sc.limits.altitude[1]
    for body, sensed in zip(sc.bodies, sc.sensed, strict=False):
        if isinstance(body, Cylinder):
            x0, x1 = body.center[0] - body.radius, body.center[0] + body.radius
        else:
            xs = box_corners(body)[:, 0]
            x0, x1 = xs.min(), xs.max()
        h = min(body.height, z_top * 1.05)
        ax.add_patch(
            Rectangle(
                (x0, 0.0),
                x1 - x0,
                h,
                facecolor=OBSTACLE_GREY if sensed else "0.82",
                edgecolor="0.3",
                linewidth=0.6,
            )
        )
        if sensed:
            half = body.side / 2.0
            ax.add_patch(
                Rectangle(
                    (body.center[0] - half, 0.0),
                    2 * half,
                    min(body.prism_height, z_top * 1.05),
                    fill=False,
                    linestyle="--",
                    edgecolor=PRISM_GREY,
                    linewidth=0.8,
                )
            )
    for s in sc.spheres:
        ax.add_patch(
            Circle(
                (s.center[0], s.center[2]),
                s.radius,
                fill=False,
                edgecolor="0.35",
                linestyle="-" if s.physical else ":",
            )
        )


def _zones(ax, record: RunRecord, offsets: np.ndarray, colors: list) -> EllipseCollection:
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
        linewidths=0.8,
        linestyles="--",
    )
    ax.add_collection(zones)
    return zones


def _figure(record: RunRecord) -> tuple[Figure, dict]:
    """The figure with everything static drawn, and the artists each frame moves."""
    sc = record.scenario
    lo, hi = scene_bounds(record)
    r = float(sc.r_pz.max())
    lo, hi = lo - r, hi + r  # room for the spheres at the edges
    lo[2] = max(lo[2], min(0.0, sc.limits.altitude[0]))
    x_span, y_span, z_span = hi - lo
    # Axes to scale: about 5.5 in wide, shrunk so that plan and elevation fit in 7 in of height.
    width = min(5.5, 7.0 * x_span / (y_span + z_span))
    left, right, bottom, top_, gap = 0.8, 2.4, 0.55, 0.4, 0.3  # margins, in
    w, h = left + width + right, bottom + width * (y_span + z_span) / x_span + gap + top_
    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    top, side = fig.subplots(2, 1, sharex=True, height_ratios=[y_span, z_span])
    fig.subplots_adjust(
        left=left / w,
        right=(left + width) / w,
        bottom=bottom / h,
        top=1 - top_ / h,
        hspace=2 * gap / (h - bottom - top_ - gap),
    )
    colors = agent_colors(record.n_agents)
    draw_obstacles_2d(top, record)
    _elevation_obstacles(side, record)
    p = record.positions
    top.scatter(p[0, :, 0], p[0, :, 1], c=colors, marker="o", s=9)
    top.scatter(sc.goals[:, 0], sc.goals[:, 1], c=colors, marker="x", s=16)
    moving: dict = {"dots": [], "zones": [], "trails": []}
    few = record.n_agents <= LEGEND_MAX_AGENTS
    for ax, (a, b) in ((top, (0, 1)), (side, (0, 2))):
        for i in range(record.n_agents if few else 0):  # the paths ahead, faint
            ax.plot(p[:, i, a], p[:, i, b], color=colors[i], linewidth=0.6, alpha=0.3)
        moving["trails"].append(
            [ax.plot([], [], color=colors[i], linewidth=1.1)[0] for i in range(record.n_agents)]
        )
        moving["zones"].append(_zones(ax, record, p[0][:, [a, b]], colors))
        moving["dots"].append(ax.scatter(p[0, :, a], p[0, :, b], c=colors, s=12, zorder=5))
        ax.set_aspect("equal", adjustable="box")
        ax.grid(True, linewidth=0.4, alpha=0.5)
    top.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), ylabel="y (m)")
    side.set(ylim=(lo[2], hi[2]), xlabel="x (m)", ylabel="z (m)")
    handles, labels = key_handles(record, [], prisms=True)
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
    if few:
        handles = [Line2D([], [], color=c, linewidth=1.6) for c in colors] + handles
        labels = list(record.ids) + labels
    fig.legend(
        handles,
        labels,
        loc="upper left",
        bbox_to_anchor=((left + width + 0.1) / w, 1 - top_ / h),
        fontsize="small",
        frameon=False,
        borderaxespad=0.0,
    )
    # the longest title, so that the layout leaves room for every frame's
    moving["title"] = fig.suptitle(_title(record, len(record.times) - 1), fontsize="medium")
    return fig, moving


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
    fig, moving = _figure(record)
    fig.set_dpi(dpi)
    artists = [
        moving["title"],
        *moving["dots"],
        *moving["zones"],
        *(line for panel in moving["trails"] for line in panel),
    ]
    for artist in artists:
        artist.set_animated(True)
    canvas = cast(FigureCanvasAgg, fig.canvas)
    p = record.positions
    few = record.n_agents <= LEGEND_MAX_AGENTS
    trail = int(round(TRAIL_SECONDS / record.dt))  # with many vehicles, only their recent path
    writer = _BlitPillowWriter(fps=fps)
    with writer.saving(fig, path, dpi):
        canvas.draw()
        background = canvas.copy_from_bbox(fig.bbox)
        for k in frames:
            canvas.restore_region(background)
            first = 0 if few else max(0, k - trail)
            for panel, (a, b) in enumerate(((0, 1), (0, 2))):
                moving["dots"][panel].set_offsets(p[k][:, [a, b]])
                moving["zones"][panel].set_offsets(p[k][:, [a, b]])
                for i, line in enumerate(moving["trails"][panel]):
                    line.set_data(p[first : k + 1, i, a], p[first : k + 1, i, b])
            moving["title"].set_text(_title(record, k))
            for artist in artists:
                fig.draw_artist(artist)
            writer.grab_frame()
