"""Distances over time (the paper's Figs. 14, 16, 20, 30).

Vehicle-vehicle: one curve per *pair* (the distance of u0 to u1 is that of u1 to u0: per-vehicle
curves of a pair lie on each other). The closest pairs are drawn in colour, each in its own
colour and line pattern, named in the key; the other pairs thin and grey. Vehicle-obstacle: one
curve per vehicle, to its nearest obstacle surface. A curve that lies on an earlier one is
drawn dashed over it and its key says on which. A swarm (more than LEGEND_MAX_AGENTS vehicles)
is drawn as bands over the vehicles: the least at every sample, the 5-95 % and the median at
up to BAND_SAMPLES samples, with its closest pairs numbered as on the top view.

The curves are sampled every ``dt``; the marked minimum is the summary's own figure
(:func:`vo3d_opt.sim.metrics.closest_vehicle_approach`, continuous along each step), so it may
lie a little below the sampled curves. Every label is placed clear of the curves and lines.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.sim.metrics import (
    Approach,
    closest_obstacle_approach,
    closest_vehicle_approach,
    nearest_obstacle_distance,
    nearest_vehicle_distance,
    pair_min_distances,
    physical_obstacle_names,
)
from vo3d_opt.sim.record import RunRecord

from .keys import marker_handle, side_legend
from .labels import place_label
from .scene import BAND_SAMPLES, chunk_samples, closest_pairs, drawn_samples, prism_margin
from .style import (
    DASHES,
    LEGEND_MAX_AGENTS,
    PALETTE,
    REFERENCE,
    agent_styles,
    new_figure,
    settle,
    styled,
)

with needs("sim", "plotting"):
    from matplotlib.axes import Axes
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

#: Pairs drawn in colour and named (the closest ones); the others are grey.
PAIR_CURVES = 5
#: The palette's darker colours: the pairs are drawn over the grey of the others.
PAIR_COLORS = tuple(PALETTE[k] for k in (0, 1, 2, 5, 6))
#: Two curves closer than this fraction of the plot's height everywhere lie on each other.
COINCIDE = 0.01
#: A dash pattern whose gaps show the curve underneath.
OVER_DASH = (0, (3, 3))
BAND_COLOR = PALETTE[0]


def distance_samples(record: RunRecord) -> np.ndarray | None:
    """The samples at which a distance figure draws a swarm's bands: None (curves) up to
    LEGEND_MAX_AGENTS vehicles, else ``BAND_SAMPLES`` of them."""
    if record.n_agents <= LEGEND_MAX_AGENTS:
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


def coinciding(d: np.ndarray) -> list[int | None]:
    """For each column of d (samples, curves), an earlier column it lies on everywhere (within
    COINCIDE of the finite values' span), or None."""
    finite = d[np.isfinite(d)]
    span = float(np.ptp(finite)) if finite.size else 0.0
    tol = COINCIDE * max(span, 1e-9)
    out: list[int | None] = []
    for k in range(d.shape[1]):
        same = None
        for j in range(k):
            gap = np.abs(d[:, k] - d[:, j])
            if np.all(np.isfinite(gap) | (d[:, k] == d[:, j])) and np.nanmax(gap) <= tol:
                same = j
                break
        out.append(same)
    return out


def draw_curves(
    ax: Axes, times: np.ndarray, d: np.ndarray, styles: list[tuple[str, Any]], names: list[str]
) -> tuple[list[Any], list[str]]:
    """Columns of d as curves in their (colour, pattern), drawn in order; one lying on an
    earlier curve is dashed over it and named "(on <earlier>)". The key's entries."""
    handles: list[Any] = []
    labels: list[str] = []
    for k, (same, (color, dash)) in enumerate(zip(coinciding(d), styles, strict=True)):
        pattern = dash if same is None else OVER_DASH
        (line,) = ax.plot(times, d[:, k], color=color, linestyle=pattern, zorder=2 + k * 1e-3)
        line.set_gid(names[k])
        handles.append(line)
        labels.append(names[k] if same is None else f"{names[k]} (on {names[same]})")
    return handles, labels


def pair_curves(ax: Axes, record: RunRecord) -> tuple[list[Any], list[str]]:
    """Every pair's distance over time: the PAIR_CURVES closest pairs (continuous minimum) in
    colour and named, the others thin and grey. The key's entries."""
    times, ids, p = record.times, record.ids, record.positions
    ii, jj, dmin = pair_min_distances(record.track[1])
    order = np.argsort(dmin, kind="stable")
    shown, rest = order[:PAIR_CURVES], order[PAIR_CURVES:]
    handles: list[Any] = []
    labels: list[str] = []
    if rest.size:
        grey = np.linalg.norm(p[:, ii[rest]] - p[:, jj[rest]], axis=-1)  # (T+1, rest)
        segments = [np.column_stack([times, grey[:, k]]) for k in range(rest.size)]
        others = LineCollection(segments, colors="0.7", linewidths=0.7, zorder=1)
        ax.add_collection(others)
        handles.append(Line2D([], [], color="0.7", linewidth=0.7))
        labels.append(f"the other {rest.size} pairs")
    d = np.linalg.norm(p[:, ii[shown]] - p[:, jj[shown]], axis=-1)
    styles = [
        (PAIR_COLORS[k % len(PAIR_COLORS)], DASHES[k % len(DASHES)]) for k in range(shown.size)
    ]
    names = [f"{ids[ii[k]]}–{ids[jj[k]]}" for k in shown]
    curves, names = draw_curves(ax, times, d, styles, names)
    return curves + handles, names + labels


def _bands(
    ax: Axes, times: np.ndarray, d: np.ndarray, samples: np.ndarray
) -> tuple[list[Any], list[str]]:
    """A swarm's distances (``swarm_bands``' d) drawn: the least over the vehicles at every
    sample, the 5-95 % band and the median at ``samples``; the key's entries."""
    t = times[samples]
    band = ax.fill_between(t, d[samples, 1], d[samples, 3], color=BAND_COLOR, alpha=0.2, lw=0)
    (median,) = ax.plot(t, d[samples, 2], color=BAND_COLOR, linewidth=1.2)
    (low,) = ax.plot(times, d[:, 0], color="k", linewidth=1.0)
    return [low, band, median], ["least over the vehicles", "5-95 % of the vehicles", "median"]


def mark_pairs(ax: Axes, pairs: list[Approach]) -> list[Any]:
    """The numbered closest pairs at (time, distance), numbers placed clear of the curves
    (layout settled). Returns the numbers."""
    ax.plot(
        [a.time for a in pairs],
        [a.distance for a in pairs],
        "o",
        color="k",
        markerfacecolor="white",
        markersize=7,
        zorder=6,
    )
    return [
        place_label(
            ax,
            str(k + 1),
            (a.time, a.distance),
            base=4.0,
            prefer=math.pi / 2,
            fontsize=9,
            fontweight="bold",
        )
        for k, a in enumerate(pairs)
    ]


def _frame(ax: Axes, record: RunRecord, *, what: str, ylabel: str) -> None:
    ax.set_ylim(bottom=0.0)
    ax.set_xlim(record.times[0], record.times[-1])
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True)
    ax.set_title(f"{record.scenario.name}: {what}")


def reference_lines(ax: Axes, lines: dict[float, str]) -> tuple[list[Any], list[str]]:
    """Horizontal reference lines {value: label}, dashed, in the reference colour."""
    handles = [
        ax.axhline(v, color=REFERENCE, linestyle=(0, (6, 3)), linewidth=1.0, zorder=1.5)
        for v in sorted(lines)
    ]
    return handles, [lines[v] for v in sorted(lines)]


def closest_marker(ax: Axes, closest: Approach) -> Any:
    """The closest approach as a black dot."""
    (dot,) = ax.plot(closest.time, closest.distance, "o", color=REFERENCE, markersize=6.5, zorder=7)
    return dot


def min_label(ax: Axes, closest: Approach) -> Any:
    """The summary's figure beside its dot, where it crosses nothing (layout settled)."""
    return place_label(
        ax,
        f"min {closest.distance:.3f} m",
        (closest.time, closest.distance),
        base=4.0,
        prefer=-math.pi / 4,
        fontsize=9,
    )


@styled
def figure_vehicle_distance(record: RunRecord) -> Figure | None:
    """The distance of every vehicle pair over time (a swarm's as bands) with the r_pz line
    (Figs. 14, 16a, 20a); None for a single vehicle."""
    closest = closest_vehicle_approach(record)
    if closest is None:
        return None
    fig = new_figure((7.0, 4.2))
    ax = fig.add_subplot()
    samples = distance_samples(record)
    pairs: list[Approach] = []
    if samples is None:
        handles, labels = pair_curves(ax, record)
    else:
        d = swarm_bands(record, nearest_vehicle_distance, samples)
        handles, labels = _bands(ax, record.times, d, samples)
        pairs = closest_pairs(record)
    lines = {float(r): f"r_pz = {r:g} m" for r in np.unique(record.scenario.r_pz)}
    more, names = reference_lines(ax, lines)
    handles += [*more, closest_marker(ax, closest)]
    names_of = record.ids
    labels += [*names, f"closest approach ({names_of[closest.agent]}, {names_of[closest.other]})"]
    if pairs:
        handles.append(marker_handle("o", 7, color="k", markerfacecolor="white"))
        labels.append("closest pairs, numbered\nas on the top view")
    # a pair's curve is the distance between its two; a band, each vehicle's to its nearest
    ylabel = (
        "distance between the pair (m)" if samples is None else "distance to nearest vehicle (m)"
    )
    _frame(ax, record, what="vehicle-vehicle distance", ylabel=ylabel)
    side_legend(ax, handles, labels)
    settle(fig)
    min_label(ax, closest)
    if pairs:
        mark_pairs(ax, pairs)
    return fig


def obstacle_margins(record: RunRecord) -> np.ndarray:
    """The prism margin of every obstacle the metrics count (bodies, then physical spheres:
    radius + margin is their protected zone, so their margin is the gap to it)."""
    sc = record.scenario
    return np.array(
        [prism_margin(b) for b in sc.bodies] + [s.r_pz - s.radius for s in sc.spheres if s.physical]
    )


@styled
def figure_obstacle_distance(record: RunRecord) -> Figure | None:
    """Each vehicle's distance to the nearest obstacle surface over time (Figs. 16b, 20b, 30;
    a swarm's as bands), with the prism margin (a vehicle outside C_pz is at least that far
    from the body); None without a physical obstacle."""
    closest = closest_obstacle_approach(record)
    if closest is None:
        return None
    margins = np.unique(obstacle_margins(record).round(9))
    if len(margins) > 3:  # many different margins: the smallest is the one that binds
        lines = {float(margins[0]): f"smallest prism margin = {margins[0]:g} m"}
    else:
        lines = {float(m): f"prism margin = {m:g} m" for m in margins}
    fig = new_figure((7.0, 4.2))
    ax = fig.add_subplot()
    samples = distance_samples(record)
    if samples is None:
        d = nearest_obstacle_distance(record)
        handles, labels = draw_curves(
            ax, record.times, d, agent_styles(record.n_agents), list(record.ids)
        )
    else:
        d = swarm_bands(record, nearest_obstacle_distance, samples)
        handles, labels = _bands(ax, record.times, d, samples)
    more, names = reference_lines(ax, lines)
    other = physical_obstacle_names(record)[closest.other]
    handles += [*more, closest_marker(ax, closest)]
    labels += [*names, f"closest approach ({record.ids[closest.agent]}, {other})"]
    _frame(
        ax,
        record,
        what="vehicle-obstacle distance",
        ylabel="distance to nearest obstacle surface (m)",
    )
    side_legend(ax, handles, labels)
    settle(fig)
    min_label(ax, closest)
    return fig
