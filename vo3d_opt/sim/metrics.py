"""Safety and timing summary of a run (contract §3) and the distance series behind the plots.

The metrics judge the vehicles' real trajectory: the control steps, or the dynamics' finer
samples when it records them (``RunRecord.track``: rotorpy's sub-steps); "step" below means one
segment between two samples. Distances between two vehicles are evaluated *continuously*: within
a step both fly straight lines, so their relative motion is linear and the closest approach on
each segment is exact (a sampled-only check could miss a pass between two samples). Distances to
obstacles are evaluated at the samples and at three interior points of every segment. A 1e-6
tolerance absorbs rounding in every threshold (distance, altitude, speed).

Swarms: the summary never forms every vehicle pair. :func:`close_pairs` finds, step by step with
a k-d tree, the pairs that come closer than the largest protected-zone (or collision) distance
and the closest pair of the run, so its cost grows with the vehicles and their near neighbours,
not with their square; every per-step array is taken a chunk of steps at a time.

Keys of :func:`summarize` beyond the contract: ``decisions`` (select() calls),
``status_counts`` (per status), ``vehicle_collisions`` / ``obstacle_collisions`` (the two parts
of ``collisions``), ``obstacle_pz_intrusions`` (vehicle–obstacle pairs whose centre ever entered
the obstacle's protected prism C_pz, or a sphere's protected zone), ``starts_inside_pz``
(vehicle pairs and vehicle–obstacle pairs already inside such a zone at t = 0, which also count
in the intrusions), ``arrival_time_max`` (s, null unless all arrived), ``path_length_ratio``
(flown path over straight start–goal distance, mean over arrived agents), ``decision_time_max_us``
and ``wall_time`` (s).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from vo3d_opt.sim.record import RunRecord
from vo3d_opt.sim.scenario import prism_contains, sphere_surface_distance

TOL = 1e-6
#: Interior points per segment at which obstacle distances are also evaluated.
OBSTACLE_SUBSAMPLES = (0.25, 0.5, 0.75)
#: Steps per chunk of the pairwise arrays, at most, and the elements per chunk (bounds memory to
#: a few hundred MB however many vehicles: the arrays grow with the square of their number).
_CHUNK = 256
CHUNK_ELEMENTS = 8_000_000
#: :func:`close_pairs` takes every pair over every segment at once up to this many
#: (segment, pair) rows (about 50 MB of temporaries), a k-d tree per step beyond.
ALL_PAIRS_ELEMENTS = 500_000

CONTRACT_KEYS = (
    "scenario",
    "formulation",
    "solver",
    "agents",
    "steps",
    "time",
    "reached",
    "all_reached",
    "min_vehicle_distance",
    "min_obstacle_distance",
    "pz_intrusions",
    "collisions",
    "altitude_violations",
    "speed_violations",
    "fallbacks",
    "decision_time_median_us",
    "decision_time_p99_us",
)


def pair_min_distances(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest approach of every vehicle pair over the whole run, along the straight segments.

    Returns (i, j, dmin) for the pairs i < j, each of shape (P,).
    """
    n = positions.shape[1]
    ii, jj = np.triu_indices(n, 1)
    dmin = np.full(ii.shape, np.inf)
    if ii.size == 0:
        return ii, jj, dmin
    last = positions.shape[0] - 1
    chunk = int(max(2, min(_CHUNK, CHUNK_ELEMENTS // ii.size)))
    for a in range(0, max(last, 1), chunk):
        b = min(a + chunk, last)
        rel = positions[a : b + 1, ii] - positions[a : b + 1, jj]  # (S+1, P, 3)
        dmin = np.minimum(dmin, np.linalg.norm(rel, axis=-1).min(axis=0))
        if b > a:
            r0, w = rel[:-1], rel[1:] - rel[:-1]
            ww = np.einsum("spk,spk->sp", w, w)
            with np.errstate(invalid="ignore", divide="ignore"):
                t = np.where(ww > 0, -np.einsum("spk,spk->sp", r0, w) / ww, 0.0)
            t = np.clip(t, 0.0, 1.0)
            closest = np.linalg.norm(r0 + t[..., None] * w, axis=-1)
            dmin = np.minimum(dmin, closest.min(axis=0))
    return ii, jj, dmin


def _segment_min(p0: np.ndarray, p1: np.ndarray, ii: np.ndarray, jj: np.ndarray) -> np.ndarray:
    """Closest approach of pairs (ii, jj) over one straight segment from p0 to p1 (N, 3) each."""
    return segment_min(p0[ii] - p0[jj], p1[ii] - p1[jj])


def segment_min(r0: np.ndarray, r1: np.ndarray) -> np.ndarray:
    """Least norm over a straight segment from ``r0`` to ``r1`` (P, 3) each, row by row (relative
    positions at the ends of a period): the same arithmetic as :func:`pair_min_distances`."""
    w = r1 - r0
    ww = np.einsum("pk,pk->p", w, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(ww > 0, -np.einsum("pk,pk->p", r0, w) / ww, 0.0)
    t = np.clip(t, 0.0, 1.0)
    ends = np.minimum(np.linalg.norm(r0, axis=-1), np.linalg.norm(r1, axis=-1))
    return np.minimum(ends, np.linalg.norm(r0 + t[:, None] * w, axis=-1))


def close_pairs(
    positions: np.ndarray,
    threshold: float,
    release: Callable[[], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, dmin), i < j: every vehicle pair whose closest approach over the run (continuous
    along the straight segments) is below ``threshold``, and the closest pair of the run
    whatever its distance (first, when it is not below ``threshold``); dmin is exact, as
    :func:`pair_min_distances` gives it.

    Step by step, a k-d tree at the segment's start proposes the pairs within ``max(threshold,
    best) + 2 × the longest step flown`` (best: the smallest distance found so far, at first the
    nearest pair at the start): no pair outside can come closer than that within the segment.
    ``release``: called every ``_CHUNK`` steps (a spilled record's ``drop_resident``).
    """
    S, n = positions.shape[0], positions.shape[1]
    empty = np.zeros(0, dtype=np.int64)
    if n < 2:
        return empty, empty, np.zeros(0)
    if max(S - 1, 1) * n * (n - 1) // 2 <= ALL_PAIRS_ELEMENTS:
        return _close_pairs_at_once(positions, threshold)
    # An upper bound of the run's smallest distance: the nearest pair at the start (inflated a
    # hair: the tree's distance may differ from numpy's in the last bit).
    bound = float(cKDTree(positions[0]).query(positions[0], k=2)[0][:, 1].min()) * (1 + 1e-9) + 1e-9
    best_key, best = -1, np.inf
    keys, dists = [], []
    for k in range(max(S - 1, 1)):
        if release is not None and k % _CHUNK == _CHUNK - 1:
            release()
        p0, p1 = positions[k], positions[min(k + 1, S - 1)]
        longest = float(np.max(np.linalg.norm(p1 - p0, axis=1)))
        reach = max(threshold, min(best, bound)) + 2.0 * longest
        pairs = cKDTree(p0).query_pairs(reach * (1 + 1e-9) + 1e-9, output_type="ndarray")
        if not pairs.size:
            continue
        ii, jj = pairs.min(axis=1), pairs.max(axis=1)
        d = _segment_min(p0, p1, ii, jj)
        m = int(np.argmin(d))
        if d[m] < best:
            best, best_key = float(d[m]), int(ii[m]) * n + int(jj[m])
        near = d < threshold
        keys.append(ii[near] * n + jj[near])
        dists.append(d[near])
    key = np.concatenate(keys) if keys else empty
    dist = np.concatenate(dists) if dists else np.zeros(0)
    order = np.argsort(key, kind="stable")
    key, dist = key[order], dist[order]
    uniq, start = np.unique(key, return_index=True)
    dmin = np.minimum.reduceat(dist, start) if uniq.size else np.zeros(0)
    if best_key >= 0 and not np.any(uniq == best_key):
        uniq, dmin = np.concatenate([[best_key], uniq]), np.concatenate([[best], dmin])
    return uniq // n, uniq % n, dmin


def _close_pairs_at_once(
    positions: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`close_pairs` of a small run (few vehicles, few steps): every pair over every
    segment in one :func:`segment_min` call instead of a k-d tree per step. The same answer:
    the tree's proposals only leave out pair-segments farther than both the threshold and the
    closest distance found, and the distances are the same arithmetic, row by row. The
    closest pair is the first (by step, then pair) at the smallest distance."""
    S, n = positions.shape[0], positions.shape[1]
    ii, jj = np.triu_indices(n, 1)
    p0 = positions[:-1] if S > 1 else positions
    p1 = positions[1:] if S > 1 else positions
    r0 = (p0[:, ii] - p0[:, jj]).reshape(-1, 3)
    r1 = (p1[:, ii] - p1[:, jj]).reshape(-1, 3)
    d = segment_min(r0, r1).reshape(-1, ii.shape[0])  # (segments, pairs)
    near = d < threshold
    dmin = np.where(near, d, np.inf).min(axis=0)
    keep = np.asarray(near.any(axis=0), dtype=bool)
    first = int(np.argmin(d))  # row-major: the earliest segment, then the lowest pair
    best = first % ii.shape[0]
    out_i, out_j, out_d = ii[keep], jj[keep], dmin[keep]
    if not keep[best]:
        out_i = np.concatenate([[ii[best]], out_i])
        out_j = np.concatenate([[jj[best]], out_j])
        out_d = np.concatenate([[d.flat[first]], out_d])
    return out_i.astype(np.int64), out_j.astype(np.int64), out_d


def _with_subsamples(positions: np.ndarray) -> np.ndarray:
    """Samples plus interior points of each segment, shape (S, N, 3)."""
    if positions.shape[0] < 2:
        return positions
    a, d = positions[:-1], positions[1:] - positions[:-1]
    inner = [a + f * d for f in OBSTACLE_SUBSAMPLES]
    return np.concatenate([positions, *inner], axis=0)


def _physical_obstacles(record: RunRecord) -> list[tuple[str, Any]]:
    """(kind, object) for every obstacle the metrics count: bodies and physical spheres."""
    sc = record.scenario
    out: list[tuple[str, Any]] = [("body", b) for b in sc.bodies]
    out += [("sphere", s) for s in sc.spheres if s.physical]
    return out


def obstacle_min_distances(
    record: RunRecord,
    positions: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(N, M) smallest centre-to-surface distance and (N, M) 'entered the protected zone', over
    the M physical obstacles, for the record's positions (or the ``positions`` given); a chunk
    of steps at a time."""
    positions = record.track[1] if positions is None else positions
    obstacles = _physical_obstacles(record)
    n = positions.shape[1]
    dist = np.full((n, len(obstacles)), np.inf)
    entered = np.zeros((n, len(obstacles)), dtype=bool)
    if not obstacles:
        return dist, entered
    for a in range(0, max(positions.shape[0] - 1, 1), _CHUNK):
        pts = _with_subsamples(positions[a : a + _CHUNK + 1])
        for m, (kind, ob) in enumerate(obstacles):
            d, e = _obstacle_distance(kind, ob, pts)
            dist[:, m] = np.minimum(dist[:, m], d.min(axis=0))
            entered[:, m] |= e.any(axis=0)
        record.drop_resident()
    return dist, entered


def _obstacle_distance(kind: str, ob: Any, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surface distance and 'inside the protected zone' of points (..., 3) for one obstacle."""
    if kind == "body":
        shrunk = pts.copy()
        horiz = pts[..., :2] - ob.center
        norm = np.linalg.norm(horiz, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            shrunk[..., :2] += np.where(norm > 0, horiz / norm * TOL, 0.0)
        shrunk[..., 2] += TOL
        return ob.surface_distance(pts), prism_contains(ob, shrunk)
    centre = np.asarray(ob.center, dtype=float)
    return (
        sphere_surface_distance(centre, ob.radius, pts),
        np.linalg.norm(pts - centre, axis=-1) < ob.r_pz - TOL,
    )


def nearest_vehicle_distance(record: RunRecord, samples: np.ndarray | None = None) -> np.ndarray:
    """(T+1, N): each vehicle's distance to its nearest other vehicle at each sample (inf alone);
    ``samples``: only those sample indices, one row each (a large run's figures)."""
    rows = np.arange(record.positions.shape[0]) if samples is None else np.asarray(samples)
    out = np.full((rows.size, record.positions.shape[1]), np.inf)
    if out.shape[1] < 2:
        return out
    for r, k in enumerate(rows):
        pk = record.positions[k]
        out[r] = cKDTree(pk).query(pk, k=2)[0][:, 1]
    return out


def nearest_obstacle_distance(record: RunRecord, samples: np.ndarray | None = None) -> np.ndarray:
    """(T+1, N): each vehicle's distance to the nearest obstacle surface (inf without any);
    ``samples``: only those sample indices."""
    p = record.positions if samples is None else record.positions[np.asarray(samples)]
    out = np.full(p.shape[:2], np.inf)
    for kind, ob in _physical_obstacles(record):
        d = (
            ob.surface_distance(p)
            if kind == "body"
            else sphere_surface_distance(np.asarray(ob.center), ob.radius, p)
        )
        out = np.minimum(out, d)
    return out


@dataclass(frozen=True)
class Approach:
    """The closest approach of a run, as the summary reports it, and where it happened.

    ``distance`` is exactly the summary's ``min_vehicle_distance`` (or ``min_obstacle_distance``);
    ``time`` (s) the moment it was reached, between samples when the minimum lies inside a step;
    ``agent`` the vehicle's index and ``other`` the other vehicle's index, or the obstacle's index
    in :func:`physical_obstacle_names` order.
    """

    distance: float
    time: float
    agent: int
    other: int


def _closest_time(rel: np.ndarray, times: np.ndarray) -> float:
    """When the relative position rel (S+1, 3), linear within each step, is shortest."""
    r0, w = rel[:-1], np.diff(rel, axis=0)
    ww = np.einsum("sk,sk->s", w, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.clip(np.where(ww > 0, -np.einsum("sk,sk->s", r0, w) / ww, 0.0), 0.0, 1.0)
    inner = np.linalg.norm(r0 + f[:, None] * w, axis=-1)
    k = int(np.argmin(inner)) if inner.size else 0
    if not inner.size or np.linalg.norm(rel[-1]) < inner[k]:
        return float(times[-1] if inner.size else times[0])
    return float(times[k] + f[k] * (times[k + 1] - times[k]))


def pz_threshold(record: RunRecord) -> float:
    """The largest distance below which a vehicle pair counts (an intrusion or a collision),
    plus the tolerance: the ``threshold`` of :func:`close_pairs` for the summary."""
    sc = record.scenario
    return float(max(np.max(sc.r_pz), 2.0 * np.max(sc.radius))) + TOL


def record_close_pairs(record: RunRecord) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`close_pairs` of the record at :func:`pz_threshold`, computed once per record."""
    cache = record.cache
    if "close_pairs" not in cache:
        cache["close_pairs"] = close_pairs(
            record.track[1], pz_threshold(record), release=record.drop_resident
        )
    return cache["close_pairs"]


def closest_vehicle_approach(
    record: RunRecord,
    pairs: tuple[np.ndarray, ...] | None = None,
) -> Approach | None:
    """The closest vehicle pair over the run (continuous, as in the summary); None with fewer
    than two vehicles. ``pairs``: (i, j, dmin) of pairs including the closest one
    (:func:`close_pairs` or :func:`pair_min_distances`), when already computed."""
    ii, jj, dmin = pairs if pairs is not None else record_close_pairs(record)
    if not dmin.size or not np.isfinite(dmin.min()):
        return None
    k = int(np.argmin(dmin))
    i, j = int(ii[k]), int(jj[k])
    times, track = record.track
    rel = track[:, i] - track[:, j]
    return Approach(float(dmin[k]), _closest_time(rel, times), i, j)


def closest_obstacle_approach(
    record: RunRecord,
    odist: np.ndarray | None = None,
) -> Approach | None:
    """The closest vehicle-obstacle approach over the run (samples and interior points, as in
    the summary); None without physical obstacles. ``odist``: :func:`obstacle_min_distances`'
    distances, when already computed."""
    if odist is None:
        odist = obstacle_min_distances(record)[0]
    if not odist.size or not np.isfinite(odist.min()):
        return None
    i, m = (int(x) for x in np.unravel_index(np.argmin(odist), odist.shape))
    kind, ob = _physical_obstacles(record)[m]
    times, track = record.track
    pts = _with_subsamples(track[:, i])
    d = (
        ob.surface_distance(pts)
        if kind == "body"
        else sphere_surface_distance(np.asarray(ob.center, dtype=float), ob.radius, pts)
    )
    t = _with_subsamples(times)[int(np.argmin(d))]
    return Approach(float(odist[i, m]), float(t), i, m)


def physical_obstacle_names(record: RunRecord) -> list[str]:
    """Names of the obstacles the metrics count, in their order: 'obstacles[k]', 'spheres[k]'."""
    sc = record.scenario
    return [f"obstacles[{k}]" for k in range(len(sc.bodies))] + [
        f"spheres[{k}]" for k, s in enumerate(sc.spheres) if s.physical
    ]


def _out_of_band(z: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return (z < lo - TOL) | (z > hi + TOL)


def _limits_and_paths(record: RunRecord) -> tuple[int, int, np.ndarray]:
    """Altitude and speed violations, and each vehicle's path length, a chunk of steps at a
    time. With sub-step samples (rotorpy) a (vehicle, step) violates a limit when any sample
    within the step does, and the path is measured along the samples."""
    sc = record.scenario
    z_lo, z_hi = sc.limits.altitude
    v_lo = sc.limits.speed[0]
    per = record.substeps
    _, track = record.track
    n = record.n_agents
    altitude = int(np.count_nonzero(_out_of_band(track[0, :, 2], z_lo, z_hi)))  # the start
    speed_bad, path = 0, np.zeros(n)
    for a in range(0, record.steps, _CHUNK):
        # the samples within steps a.. (rows 1 + k per .. (k + 1) per): one count per step
        z = track[a * per + 1 : (a + _CHUNK) * per + 1, :, 2]
        altitude += int(np.count_nonzero(_out_of_band(z, z_lo, z_hi).reshape(-1, per, n).any(1)))
        speed = np.linalg.norm(record.velocities[a : a + _CHUNK], axis=-1)
        slow = record.decided[a : a + _CHUNK] & (speed < v_lo - TOL)
        if record.sample_velocities is not None:  # the fastest sample within each step
            fine = np.linalg.norm(
                record.sample_velocities[a * per + 1 : (a + _CHUNK) * per + 1], axis=-1
            )
            speed = fine.reshape(-1, per, fine.shape[1]).max(axis=1)
        bad = (speed > sc.max_speed[None, :] + TOL) | slow
        speed_bad += int(np.count_nonzero(bad))
        steps = np.diff(track[a * per : (a + _CHUNK) * per + 1], axis=0)
        path += np.linalg.norm(steps, axis=-1).sum(axis=0)
        record.drop_resident()
    return altitude, speed_bad, path


def _status_counts(record: RunRecord) -> tuple[dict[str, int], int]:
    """How many decisions ended with each status, and how many there were, from the codes (a
    chunk of steps at a time: no string per decision)."""
    names = record.status_names
    per_code = np.zeros(len(names), dtype=np.int64)
    for a in range(0, record.steps, _CHUNK):
        codes = record.status_codes[a : a + _CHUNK][record.decided[a : a + _CHUNK]]
        per_code += np.bincount(codes, minlength=len(names))
    counts = {str(names[c]): int(m) for c, m in enumerate(per_code) if m}
    return counts, int(per_code.sum())


def decision_times_us(record: RunRecord) -> np.ndarray:
    """The finite decision times (µs) of the decisions taken, in step order, one array filled a
    chunk of steps at a time (a spilled record's pages let go of as it goes)."""
    out = np.empty(int(np.count_nonzero(record.decided)))
    m = 0
    for a in range(0, record.steps, _CHUNK):
        t = record.decision_times[a : a + _CHUNK][record.decided[a : a + _CHUNK]]
        t = t[np.isfinite(t)]
        out[m : m + t.size] = t * 1e6
        m += t.size
        record.drop_resident()
    return out[:m]


def summarize(record: RunRecord) -> dict[str, Any]:
    """The JSON summary of contract §3 (exact keys first) plus the extra keys listed above."""
    sc = record.scenario
    n, steps = record.n_agents, record.steps
    r_pz, radius = sc.r_pz, sc.radius

    ii, jj, dmin = record_close_pairs(record)
    closest_vehicle = closest_vehicle_approach(record, (ii, jj, dmin))
    pz_limit = np.maximum(r_pz[ii], r_pz[jj])
    vehicle_pz = int(np.count_nonzero(dmin < pz_limit - TOL))
    vehicle_coll = int(np.count_nonzero(dmin < radius[ii] + radius[jj] - TOL))
    si, sj, start_d = close_pairs(record.positions[:1], pz_threshold(record))  # t = 0
    starts_pz = int(np.count_nonzero(start_d < np.maximum(r_pz[si], r_pz[sj]) - TOL))

    odist, entered = obstacle_min_distances(record)
    closest_obstacle = closest_obstacle_approach(record, odist)
    obstacle_coll = int(np.count_nonzero(odist < radius[:, None] - TOL))
    obstacle_pz = int(np.count_nonzero(entered))
    if odist.size:
        starts_pz += int(np.count_nonzero(obstacle_min_distances(record, record.positions[:1])[1]))

    altitude_violations, speed_violations, steps_flown = _limits_and_paths(record)

    counts, decisions = _status_counts(record)
    fallbacks = int(sum(c for s, c in counts.items() if s != "optimal"))
    times_us = decision_times_us(record)
    t_max = t_mid = t_99 = None
    if times_us.size:  # order statistics: the same numbers with the array reordered in place
        t_max = float(times_us.max())
        t_mid = float(np.median(times_us, overwrite_input=True))
        t_99 = float(np.percentile(times_us, 99, overwrite_input=True))

    reached_mask = record.arrived[-1]
    arrival = record.arrival_times()
    straight = np.linalg.norm(sc.goals - sc.starts, axis=1)
    ratio_ok = reached_mask & (straight > 0)

    return {
        "scenario": sc.name,
        "formulation": record.formulation,
        "solver": record.solver,
        "agents": n,
        "steps": steps,
        "time": round(steps * record.dt, 9),
        "reached": int(np.count_nonzero(reached_mask)),
        "all_reached": bool(reached_mask.all()),
        "min_vehicle_distance": closest_vehicle.distance if closest_vehicle else None,
        "min_obstacle_distance": closest_obstacle.distance if closest_obstacle else None,
        "pz_intrusions": vehicle_pz,
        "collisions": vehicle_coll + obstacle_coll,
        "altitude_violations": altitude_violations,
        "speed_violations": speed_violations,
        "fallbacks": fallbacks,
        "decision_time_median_us": t_mid,
        "decision_time_p99_us": t_99,
        # extras
        "decisions": decisions,
        "status_counts": dict(sorted(counts.items())),
        "vehicle_collisions": vehicle_coll,
        "obstacle_collisions": obstacle_coll,
        "obstacle_pz_intrusions": obstacle_pz,
        "starts_inside_pz": starts_pz,
        "arrival_time_max": float(np.nanmax(arrival)) if reached_mask.all() else None,
        "path_length_ratio": (
            float(np.mean(steps_flown[ratio_ok] / straight[ratio_ok])) if ratio_ok.any() else None
        ),
        "decision_time_max_us": t_max,
        "wall_time": round(float(record.wall_time), 6),
    }
