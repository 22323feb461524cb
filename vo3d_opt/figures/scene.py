"""What the figures read from a run: samples of its record, its extent, the obstacles' names and
protected prisms as the planner turns them, and the protected zones to draw."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from vo3d_opt.sim.metrics import (
    CHUNK_ELEMENTS,
    Approach,
    close_pairs,
    closest_obstacle_approach,
    closest_vehicle_approach,
    pz_threshold,
)
from vo3d_opt.sim.record import RunRecord
from vo3d_opt.types import Box, Cylinder

#: Above this many agents the paths are drawn as one collection, through samples of the record
#: (a thousand separate lines take a matplotlib figure most of a minute).
SWARM_AGENTS = 100
#: A swarm's figures (more than SWARM_AGENTS) read at most this many positions in all, each
#: path sampled evenly in time (first and last sample kept), and its distance bands at most
#: BAND_SAMPLES times: a 10,000-agent run of 2,600 steps has 26 million positions (630 MB).
PLOT_POINTS = 2_000_000
BAND_SAMPLES = 500
#: How many of the closest vehicle pairs a swarm's figures mark and number.
CLOSEST_PAIRS = 5
#: "closest": the protected spheres of the closest pair at its closest approach.
DEFAULT_ZONES = "closest"


def xy(p: Sequence[float] | np.ndarray) -> tuple[float, float]:
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
    horizontally a vehicle is outside it beyond L_pz/2 from the axis (section 4.1); vertically
    it reaches h_pz."""
    return float(
        min(body.side / 2.0 - body.footprint_extent() / 2.0, body.prism_height - body.height)
    )


def prism_square(body: Cylinder | Box, toward: np.ndarray) -> np.ndarray:
    """(4, 2) corners of the protected prism's square footprint (side L_pz) turned, as the
    planner turns it (section 4.1), so that one side faces the point ``toward``."""
    c = np.asarray(body.center, dtype=float)
    h = np.asarray(toward, dtype=float)[:2] - c
    norm = float(np.hypot(*h))
    h = h / norm if norm > 1e-9 else np.array([1.0, 0.0])
    s = np.array([-h[1], h[0]])
    half = body.side / 2.0
    return np.array([c + half * (a * h + b * s) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


def nearest_passes(record: RunRecord) -> list[np.ndarray | None]:
    """For every body, where the vehicle that came nearest its axis was then (x, y, z): the
    point its protected prism is drawn facing; None without vehicles. Read from the drawn
    samples (the square's turn, not a distance, depends on it)."""
    p = drawn_positions(record)
    out: list[np.ndarray | None] = []
    for body in record.scenario.bodies:
        if not p.size:
            out.append(None)
            continue
        d = np.linalg.norm(p[..., :2] - np.asarray(body.center), axis=-1)
        k, i = np.unravel_index(int(np.argmin(d)), d.shape)
        out.append(np.array(p[k, i], dtype=float))
    return out


def obstacle_names(record: RunRecord) -> tuple[list[str], list[str]]:
    """The names the summary gives the bodies and the spheres: 'obstacles[k]', 'spheres[k]'
    (``vo3d_opt.sim.metrics.physical_obstacle_names``; spheres that are not physical keep
    their index in the scenario's list)."""
    sc = record.scenario
    return [f"obstacles[{k}]" for k in range(len(sc.bodies))], [
        f"spheres[{k}]" for k in range(len(sc.spheres))
    ]


def drawn_samples(n_samples: int, budget: int) -> np.ndarray:
    """Indices of at most ``budget`` (>= 2) samples of ``n_samples``, evenly spread, the first
    and the last kept (all of them when there are no more)."""
    if n_samples <= budget:
        return np.arange(n_samples)
    return np.unique(np.linspace(0, n_samples - 1, budget).round().astype(np.int64))


def drawn_indices(record: RunRecord) -> np.ndarray:
    """The samples the path figures draw: all of them, or a swarm's ``PLOT_POINTS``."""
    if record.n_agents <= SWARM_AGENTS:
        return np.arange(record.positions.shape[0])
    budget = max(2, PLOT_POINTS // record.n_agents)
    return drawn_samples(record.positions.shape[0], budget)


def drawn_positions(record: RunRecord) -> np.ndarray:
    """The positions the path figures draw (:func:`drawn_indices`)."""
    if record.n_agents <= SWARM_AGENTS:
        return record.positions
    return record.positions[drawn_indices(record)]


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


def closest_pairs(record: RunRecord, count: int = CLOSEST_PAIRS) -> list[Approach]:
    """The ``count`` vehicle pairs that came closest, closest first, each at its closest
    approach (continuous along the steps, as the summary's ``min_vehicle_distance``: the first
    is the summary's); only pairs that came within twice the protected distance, and always
    the closest one. Computed once per record."""
    key = f"figure_closest_pairs_{count}"
    if key not in record.cache:
        times, track = record.track
        ii, jj, d = close_pairs(track, 2.0 * pz_threshold(record), release=record.drop_resident)
        found = []
        for k in np.argsort(d, kind="stable")[:count]:
            pair = (ii[k : k + 1], jj[k : k + 1], d[k : k + 1])
            approach = closest_vehicle_approach(record, pairs=pair)
            if approach is not None:
                found.append(approach)
        record.cache[key] = found
    return list(record.cache[key])


# ------------------------------------------------------------------------- protected zones

#: 'closest', 'none' / None, times in s, or ZoneSnapshots already worked out.
Zones = str | Sequence[float] | Sequence["ZoneSnapshot"] | None


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


def _closest_snapshot(record: RunRecord) -> list[ZoneSnapshot]:
    """The closest vehicle pair at its closest approach (a lone vehicle at its closest
    obstacle approach)."""
    pair = closest_vehicle_approach(record)
    if pair is not None:
        who, what = [pair.agent, pair.other], "closest approach"
    else:
        pair = closest_obstacle_approach(record)
        if pair is None:
            return []
        who, what = [pair.agent], "closest obstacle approach"
    idx = np.array(who)
    label = f"protected zone r_pz at the\n{what} (t = {pair.time:.1f} s)"
    return [ZoneSnapshot(pair.time, idx, positions_at(record, pair.time)[idx], label)]


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
        return _closest_snapshot(record)
    out = []
    for t in zones:
        if isinstance(t, bool) or not isinstance(t, (int, float, np.floating, np.integer)):
            raise ValueError(f"zones: {t!r} is not a time in s")
        t = float(t)
        if not (math.isfinite(t) and t >= 0):
            raise ValueError(f"zones: times must be finite and non-negative, got {t!r}")
        idx = np.arange(record.n_agents)
        label = f"protected zones r_pz at t = {t:g} s"
        out.append(ZoneSnapshot(t, idx, positions_at(record, t)[idx], label))
    return out


def scene_bounds(record: RunRecord, snaps: Sequence[ZoneSnapshot] = ()) -> np.ndarray:
    """(2, 3) lower and upper corners of what a view shows: paths, goals, obstacles with their
    protected prisms turned any way (up to the altitude ceiling), spheres and the drawn
    protected spheres."""
    sc = record.scenario
    pts = [position_bounds(record), sc.goals]
    z_top = sc.limits.altitude[1]
    for body in sc.bodies:
        r = body.side / math.sqrt(2.0)  # the turned square's corners reach this far
        top = min(body.height, z_top)
        c = body.center
        pts.append(np.array([[c[0] - r, c[1] - r, 0.0], [c[0] + r, c[1] + r, top]]))
    for s in sc.spheres:
        pts.append(np.asarray(s.center) + np.array([[-1.0], [1.0]]) * s.radius)
    for snap in snaps:
        r = record.scenario.r_pz[snap.agents][:, None]
        pts += [snap.positions - r, snap.positions + r]
    allp = np.concatenate(pts)
    return np.stack([allp.min(axis=0), allp.max(axis=0)])
