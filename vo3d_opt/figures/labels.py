"""Labels placed where they cross nothing: no line, no filled shape, no marker, no other label.

A label is tried at points around its anchor, nearest first, and kept at the first whose box
(as drawn, in display units) is inside the axes and clear of everything else there; a label
set off further than a small gap gets a thin leader line to its anchor. Only when every place
is taken does it go where it crosses the fewest things. :func:`crossings` is the same test,
so that tests can check a figure's labels.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vo3d_opt.extras import needs

with needs("sim", "plotting"):
    from matplotlib.axes import Axes
    from matplotlib.collections import LineCollection, PathCollection, PolyCollection
    from matplotlib.colors import to_rgba
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from matplotlib.path import Path as MplPath
    from matplotlib.text import Annotation, Text
    from matplotlib.transforms import Bbox


#: Offsets (points) beyond the anchor's own radius at which a label is tried: finely near it,
#: so that a label sits as close to what it names as the clutter allows.
RINGS = (1.0, 3.0, 5.0, 7.0, 9.0, 12.0, 15.0, 19.0, 24.0, 30.0, 38.0, 48.0, 60.0, 75.0, 92.0)
#: Beyond this many points past the anchor's radius a label gets a leader line to it.
LEADER = 10.0
#: Directions tried on each ring.
DIRECTIONS = 16
#: A label must be this many times nearer its own anchor than any rival's (``place_label``).
CLAIM = 1.5
#: Room (pixels) kept around a label's box.
PAD = 2.0


@dataclass
class Clutter:
    """What a label must not cross, in display units."""

    lines: list[MplPath] = field(default_factory=list)
    filled: list[MplPath] = field(default_factory=list)
    boxes: list[Bbox] = field(default_factory=list)

    def hits(self, box: Bbox, cap: float = math.inf) -> int:
        """How many things ``box`` crosses (counting stops at ``cap``)."""
        tests = itertools.chain(
            (box.overlaps(b) for b in self.boxes),
            (p.intersects_bbox(box, filled=True) for p in self.filled),
            (p.intersects_bbox(box, filled=False) for p in self.lines),
        )
        count = 0
        for hit in tests:
            count += bool(hit)
            if count >= cap:
                break
        return count

    def crossed(self, box: Bbox) -> bool:
        """Whether ``box`` crosses anything (stops at the first)."""
        return (
            any(box.overlaps(b) for b in self.boxes)
            or any(p.intersects_bbox(box, filled=True) for p in self.filled)
            or any(p.intersects_bbox(box, filled=False) for p in self.lines)
        )


def _marker_boxes(points: np.ndarray, size_px: float) -> list[Bbox]:
    h = size_px / 2.0
    return [Bbox([[x - h, y - h], [x + h, y + h]]) for x, y in points if np.isfinite([x, y]).all()]


def _line_clutter(line: Line2D, out: Clutter, dpi: float) -> None:
    path = line.get_transform().transform_path(line.get_path())
    vertices = np.asarray(path.vertices)
    if line.get_linestyle() not in ("None", "none", "", " ") and len(vertices) > 1:
        out.lines.append(path)
    if line.get_marker() not in (None, "None", "none", "", " "):
        out.boxes += _marker_boxes(vertices, line.get_markersize() * dpi / 72.0)


def _collection_clutter(coll: Any, out: Clutter, dpi: float) -> None:
    if isinstance(coll, LineCollection):
        t = coll.get_transform()
        out.lines += [t.transform_path(p) for p in coll.get_paths()]
    elif isinstance(coll, PathCollection) and len(offsets := np.asarray(coll.get_offsets())):
        pts = coll.get_offset_transform().transform(offsets)
        sizes = coll.get_sizes()
        size = math.sqrt(float(np.max(sizes))) * dpi / 72.0 if len(sizes) else 0.0
        out.boxes += _marker_boxes(pts, size)
    elif isinstance(coll, PolyCollection) and str(coll.get_gid()).startswith("avoid"):
        t = coll.get_transform()
        out.filled += [t.transform_path(p) for p in coll.get_paths()]


def clutter(
    ax: Axes, renderer: Any, *, skip: Iterable[Any] = (), owner: str | None = None
) -> Clutter:
    """Everything in ``ax`` a label must not cross (as last drawn), but the artists ``skip``:
    lines, line collections, markers and scatter points, patches (filled ones as areas, others
    by their outline), collections with gid "avoid" or "avoid <name>" as areas (but those of
    the label's ``owner``, the name it is), and every text."""
    skipped = {id(a) for a in skip}
    if owner is not None:
        skipped |= {id(c) for c in ax.collections if c.get_gid() == f"avoid {owner}"}
    out = Clutter()
    dpi = ax.figure.dpi
    for line in ax.lines:
        if line.get_visible() and id(line) not in skipped:
            _line_clutter(line, out, dpi)
    for coll in ax.collections:
        if coll.get_visible() and id(coll) not in skipped:
            _collection_clutter(coll, out, dpi)
    for patch in ax.patches:
        if not patch.get_visible() or id(patch) in skipped:
            continue
        path = patch.get_transform().transform_path(patch.get_path())
        (out.filled if _is_filled(patch) else out.lines).append(path)
    for text in ax.texts:
        if text.get_visible() and id(text) not in skipped and text.get_text():
            out.boxes.append(text_box(text, renderer).padded(PAD))
            arrow = getattr(text, "arrow_patch", None)
            if arrow is not None:  # a leader line
                out.lines.append(arrow.get_transform().transform_path(arrow.get_path()))
    return out


def text_box(text: Text, renderer: Any) -> Bbox:
    """The box of a text's letters, without an annotation's leader line."""
    if isinstance(text, Annotation):
        text.update_positions(renderer)  # where its offset puts the letters
    return Text.get_window_extent(text, renderer)


def _is_filled(patch: Patch) -> bool:
    return bool(patch.get_fill()) and to_rgba(patch.get_facecolor())[3] > 0


def _alignment(angle: float) -> tuple[str, str]:
    c, s = math.cos(angle), math.sin(angle)
    ha = "left" if c > 0.35 else "right" if c < -0.35 else "center"
    va = "bottom" if s > 0.35 else "top" if s < -0.35 else "center"
    return ha, va


def candidates(
    base: float, prefer: float, reach: float = math.inf
) -> list[tuple[float, float, float]]:
    """(dx, dy, radius) in points, ring by ring from ``base`` out to ``base + reach``, each
    ring starting at the direction ``prefer`` (radians)."""
    out = []
    step = 2.0 * math.pi / DIRECTIONS
    for ring in (r for r in RINGS if r <= reach):
        r = base + ring
        for k in range(DIRECTIONS):
            a = prefer + step * ((k + 1) // 2) * (1 if k % 2 else -1)
            out.append((r * math.cos(a), r * math.sin(a), r))
    return out


def _gaps(box: Bbox, points: np.ndarray) -> np.ndarray:
    """Distances (display units) from points (k, 2) to the nearest point of a box."""
    dx = np.maximum.reduce([box.x0 - points[:, 0], np.zeros(len(points)), points[:, 0] - box.x1])
    dy = np.maximum.reduce([box.y0 - points[:, 1], np.zeros(len(points)), points[:, 1] - box.y1])
    return np.hypot(dx, dy)


@dataclass(frozen=True)
class _Try:
    """A place tried for a label: its offset (points) and ring radius, its box (display)."""

    dx: float
    dy: float
    r: float
    box: Bbox


def _tries(
    own: np.ndarray, size: Bbox, base: float, prefer: float, px: float, reach: float
) -> list[_Try]:
    """The boxes of a label of ``size`` at each :func:`candidates` offset from ``own``, each
    aligned so that it grows away from the anchor."""
    out = []
    for dx, dy, r in candidates(base, prefer, reach):
        ha, va = _alignment(math.atan2(dy, dx))
        x0 = own[0] + dx * px - {"left": 0.0, "center": 0.5, "right": 1.0}[ha] * size.width
        y0 = own[1] + dy * px - {"bottom": 0.0, "center": 0.5, "top": 1.0}[va] * size.height
        out.append(_Try(dx, dy, r, Bbox.from_bounds(x0, y0, size.width, size.height).padded(PAD)))
    return out


def _penalty(box: Bbox, frame: Bbox, own: np.ndarray, others: np.ndarray) -> int:
    """1000 for a box out of the axes, 100 for each rival anchor it is not far enough from."""
    inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
    mine = float(_gaps(box, own.reshape(1, 2))[0])
    return (0 if inside else 1000) + 100 * int(np.sum(_gaps(box, others) < CLAIM * mine))


def _least_crossing(tries: list[_Try], penalties: list[int], around: Clutter) -> _Try:
    """Failing a free place: never out of the axes, then as few crossings as can be, then as
    clear of the rivals as can be."""
    inside = [(p, t) for p, t in zip(penalties, tries, strict=True) if p < 1000]
    pool = sorted(inside or list(zip(penalties, tries, strict=True)), key=lambda pt: pt[0])
    free = next((t for _, t in pool if not around.crossed(t.box)), None)
    if free is not None:  # the clearest of the places that cross nothing
        return free
    best: tuple[int, int, _Try] | None = None
    for penalty, t in pool:
        hits = around.hits(t.box, cap=best[0] + 1 if best else math.inf)
        if best is None or (hits, penalty) < best[:2]:
            best = (hits, penalty, t)
    assert best is not None
    return best[2]


def place_label(
    ax: Axes,
    label: str,
    anchor: Sequence[float],
    *,
    base: float = 3.0,
    prefer: float = -math.pi / 4,
    skip: Iterable[Any] = (),
    rivals: Sequence[Sequence[float]] = (),
    reach: float = math.inf,
    optional: bool = False,
    around: Clutter | None = None,
    **text_kw: Any,
) -> Annotation | None:
    """Put ``label`` near ``anchor`` (data coordinates) where it crosses nothing (module
    docstring); failing that, where it crosses the fewest things. ``base``: points from the
    anchor to the first ring (the anchor's own size); ``prefer``: the direction tried first,
    radians; ``skip``: artists it may cross; ``rivals``: other anchors (data coordinates) the
    label must be farther from than from its own (CLAIM times), so that it is not read as
    theirs; ``reach``: the farthest ring tried (points past ``base``); ``optional``: no label
    (None) rather than one that crosses something; ``around``: the axes' :func:`clutter`
    when already gathered (labelling many things), to which the label is added. The figure's
    layout must be settled (``style.settle``) so that the boxes are the drawn ones."""
    renderer = ax.figure.canvas.get_renderer()  # type: ignore[attr-defined]
    if around is None:
        around = clutter(ax, renderer, skip=skip, owner=label)
    frame = ax.get_window_extent(renderer)
    own = ax.transData.transform(np.asarray(anchor, dtype=float).reshape(1, 2))[0]
    others = ax.transData.transform(np.asarray(rivals, dtype=float).reshape(-1, 2))
    at = (float(anchor[0]), float(anchor[1]))
    text = ax.annotate(
        label, at, xytext=(0, 0), textcoords="offset points", ha="left", va="bottom", **text_kw
    )
    size = text_box(text, renderer)  # the box at the anchor; each try is a shift of it
    text.remove()
    tries = _tries(own, size, base, prefer, ax.figure.dpi / 72.0, reach)
    penalties = [_penalty(t.box, frame, own, others) for t in tries]
    fair = (t for t, p in zip(tries, penalties, strict=True) if p == 0)
    chosen = next((t for t in fair if not around.crossed(t.box)), None)
    if chosen is None and optional:
        return None
    if chosen is None:
        chosen = _least_crossing(tries, penalties, around)
    ha, va = _alignment(math.atan2(chosen.dy, chosen.dx))
    if chosen.r > base + LEADER:
        leader = {"arrowstyle": "-", "lw": 0.6, "color": "0.3", "shrinkA": 1.0, "shrinkB": base}
        text_kw = {**text_kw, "arrowprops": leader}
    placed = ax.annotate(
        label,
        at,
        xytext=(chosen.dx, chosen.dy),
        textcoords="offset points",
        ha=ha,
        va=va,
        **text_kw,
    )
    around.boxes.append(chosen.box)
    arrow = placed.arrow_patch
    if arrow is not None:
        placed.update_positions(renderer)
        around.lines.append(arrow.get_transform().transform_path(arrow.get_path()))
    return placed


def crossings(ax: Axes, text: Text) -> int:
    """How many things of ``ax`` the drawn ``text`` crosses (its own leader line aside)."""
    renderer = ax.figure.canvas.get_renderer()  # type: ignore[attr-defined]
    around = clutter(ax, renderer, skip=[text], owner=text.get_text())
    return around.hits(text_box(text, renderer))
