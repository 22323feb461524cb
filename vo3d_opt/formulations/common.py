"""What every formulation shares: the options, the VOs of one decision (built by the same
compiled parts for the compiled kernel and for the Python formulations alike: ``build_vos``), the
limits as linear constraints, the exact safety check and the time to the first intrusion.

Compiled code receives the options as a ``Config`` and the limits as ``Bounds`` (NamedTuples of
numbers and arrays); the Python formulations wrap the same values in an ``Encounter``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Annotated, Literal, NamedTuple

import numpy as np
from pydantic import Field, StrictBool

from .._jit import entry, inline, jit
from ..geometry import (
    CORRECTIONS,
    AvoidancePlanes,
    Corrections,
    VOCones,
    VOPyramids,
    build_cones,
    build_planes,
    build_pyramids,
    default_phis,
    in_vos,
)
from ..geometry.cone import NO_VIRTUAL_SPHERE, TAU_MIN, min_speed, offset
from ..geometry.membership import (
    NO_HORIZON,
    closest_approach,
    entry_time,
    heads_into,
    in_cone,
    in_pyramid,
)
from ..geometry.pyramid import prism_rows
from ..geometry.sections import generator_angles
from ..solvers import NLP, QP, Result
from ..status import Status
from ..types import AgentState, Box, Cylinder, Limits, Model, Neighbor

#: Tolerance (m/s) on the speed and altitude limits when checking a candidate.
LIMIT_TOL = 1e-6
#: With ``pz_buffer``, the planning sphere grows by at most this share of the remaining gap.
BUFFER_GAP_SHARE = 0.9
#: Cap on the time to intrusion (s) when comparing least-bad candidates ("never").
NEVER = 1e9
#: A prism whose top reaches the ceiling is planned this much (m) above the vehicle and the
#: ceiling: no velocity's ray passes over it.
OVER_THE_CEILING = 1e3

Solve = Callable[[QP], Result]
SolveNLP = Callable[[NLP], Result]

_Deg = Annotated[float, Field(gt=0, le=180, allow_inf_nan=False)]


class Config(NamedTuple):
    """The options as compiled code reads them (``Options.config``). Across the boundary from
    Python they travel as three arrays (``Options.packed``; ``config_of`` rebuilds this), which
    numba dispatches much faster than a NamedTuple."""

    reciprocal: bool
    horizon: float  # s; NO_HORIZON (< 0) for none
    pz_buffer: float  # m
    margin: float  # m/s
    corrections: Corrections
    phi: np.ndarray  # (P,) avoidance-plane angles, rad
    cos_phi: np.ndarray  # (P,) their cosines
    sin_phi: np.ndarray  # (P,) and sines
    t: np.ndarray  # (K,) the generator angles the rows linearise at (eq. 12)
    cos_t: np.ndarray  # (K,) their cosines
    sin_t: np.ndarray  # (K,) and sines
    speed_levels: int  # the sampled grid: speeds v_min..v_max ...
    heading_step: float  # ... every this many rad on each plane
    closing_guard: bool  # see Options and limit_rows
    least_bad_escape: bool  # see Options and fallback.least_bad
    fine_fallback: bool  # see Options and fallback.grid_of


class Bounds(NamedTuple):
    """The limits of one decision as compiled code reads them."""

    v_min: float
    v_max: float
    z_min: float
    z_max: float
    acceleration: float  # m/s² per axis; NaN for none
    dt: float

    @classmethod
    def of(cls, limits: Limits, dt: float) -> Bounds:
        return cls(*bounds_array(limits, dt).tolist())


def bounds_array(limits: Limits, dt: float) -> np.ndarray:
    """(6,) v_min, v_max, z_min, z_max, acceleration (NaN: none), dt: ``Bounds`` as one array."""
    acc = np.nan if limits.acceleration is None else limits.acceleration
    return np.array(
        [limits.speed[0], limits.speed[1], limits.altitude[0], limits.altitude[1], acc, dt],
        dtype=float,
    )


class VOs(NamedTuple):
    """The VO cones and pyramids of one decision (cones first wherever they are numbered
    together), and the preferred velocity clamped to v_max."""

    cones: VOCones
    pyramids: VOPyramids
    v_pref: np.ndarray


class Options(Model):
    """Formulation options (the selector's keyword arguments), validated: a wrong or unknown
    option raises a one-line ``ValueError`` (``InputError``) naming it, ``Options: margin: ...``
    (``model_validate``, which scenario files use, keeps pydantic's structured errors)."""

    plane_step_deg: _Deg = 10.0  # avoidance planes every this many degrees in [-90, 90]
    heading_step_deg: _Deg = 10.0  # sampled: polar grid, heading resolution in each plane
    speed_levels: Annotated[int, Field(ge=2, strict=True)] = 9  # sampled: speeds v_min..v_max
    polygon_sides: Annotated[int, Field(ge=3, strict=True)] = 24  # inscribed speed polygon
    reciprocal: StrictBool = False  # RVO-style: apex (V_A + V_B)/2 for cooperative neighbours
    horizon: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None  # s; None: infinite
    # Literal of the names in CORRECTIONS, which pydantic reads at runtime and mypy cannot
    corrections: frozenset[Literal[tuple(CORRECTIONS)]] | None = None  # type: ignore[valid-type]
    # generator samples of eq. (12), sampled; the same for plane_qp's tangent points
    n_samples: Annotated[int, Field(ge=8, strict=True)] = 72
    qp_samples: Annotated[int, Field(ge=8, strict=True)] = 36
    pz_buffer: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0  # m; see build_vos
    margin: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 1e-3  # m/s; linearised VO
    # half-spaces are pushed out by this much, so that an answer on the boundary (within a
    # solver's tolerance) is still strictly outside the VO; sampled candidates keep it too
    # a limit row per cooperative neighbour near its zone: the speed towards it at most half
    # the gap per dt, so that no two vehicles running it enter each other's zones within a step
    # (limit_rows; its conditions: formulations/plane_qp.md)
    closing_guard: StrictBool = False
    # the least-bad fallback, when every velocity it tries enters a zone at once (A inside
    # planning spheres, closing on one whichever way it turns): the one that closes slowest
    # on the zones A is inside, not the one nearest the preferred velocity (fallback.least_bad;
    # on by default since the whole N = 10,000 swap: off, 550 pairs collided flying straight on)
    least_bad_escape: StrictBool = True
    # the fallbacks' grid (when no QP answer is safe) with at least the default one's speeds
    # and headings (FINE_SPEED_LEVELS, FINE_HEADING_STEP: denser, though it need not hold every
    # point of a coarser grid) in a decision with something that does not avoid: an obstacle's
    # VO pyramid in reach or any non-cooperative neighbour (fallback.has_hazard, grid_of). A
    # no-op with the default grid; with a coarse one (FAST_OPTIONS) it is what keeps
    # obstacles' zones clear: under an acceleration limit few points of an 8 x 3 grid can be
    # reached, and an obstacle does not take its share of the avoidance
    fine_fallback: StrictBool = True

    @cached_property
    def packed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(values, plane table, generator table): the scalars of ``Config`` (correction flags
        as 0/1), (phi, cos phi, sin phi) of the planes, (t, cos t, sin t) of the generators."""
        t, phi = generator_angles(self.qp_samples), default_phis(self.plane_step_deg)
        corr = Corrections.of(self.corrections)
        values = np.array(
            [
                self.reciprocal,
                NO_HORIZON if self.horizon is None else self.horizon,
                self.pz_buffer,
                self.margin,
                self.speed_levels,
                math.radians(self.heading_step_deg),
                self.closing_guard,
                self.least_bad_escape,
                self.fine_fallback,
                *corr,  # last: a seventh correction would not shift the others
            ],
            dtype=float,
        )
        return (
            values,
            np.stack([phi, np.cos(phi), np.sin(phi)]),
            np.stack([t, np.cos(t), np.sin(t)]),
        )

    @cached_property
    def config(self) -> Config:
        return py_config_of(*self.packed)


#: The fallbacks' grid in a decision with something that does not avoid (``fine_fallback``):
#: at least the default grid's speeds and headings (rad).
FINE_SPEED_LEVELS: int = Options.model_fields["speed_levels"].default
FINE_HEADING_STEP: float = math.radians(Options.model_fields["heading_step_deg"].default)


@jit
def config_of(values: np.ndarray, plane_tab: np.ndarray, gen_tab: np.ndarray) -> Config:
    """``Config`` from ``Options.packed``."""
    corr = Corrections(  # last in ``packed``
        values[9] > 0,
        values[10] > 0,
        values[11] > 0,
        values[12] > 0,
        values[13] > 0,
        values[14] > 0,
    )
    return Config(
        values[0] > 0,
        values[1],
        values[2],
        values[3],
        corr,
        plane_tab[0],
        plane_tab[1],
        plane_tab[2],
        gen_tab[0],
        gen_tab[1],
        gen_tab[2],
        int(values[4]),
        values[5],
        values[6] > 0,
        values[7] > 0,
        values[8] > 0,
    )


@jit
def bounds_of(values: np.ndarray) -> Bounds:
    """``Bounds`` from ``bounds_array``."""
    return Bounds(values[0], values[1], values[2], values[3], values[4], values[5])


@entry
def py_config_of(values: np.ndarray, plane_tab: np.ndarray, gen_tab: np.ndarray) -> Config:
    """``config_of`` for Python callers."""
    return config_of(values, plane_tab, gen_tab)


# ------------------------------------------------------------------------------- compiled core


@jit
def build_vos(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> VOs:
    """The VOs of one decision. ``nbrs`` (n, 8): position, velocity, r_pz, cooperative (1/0);
    ``prisms`` (m, 4): x, y, L_pz, h_pz of the protected prisms.

    - The preferred velocity beyond reach is aimed at the reachable one (clamped to v_max).
    - With a horizon, zones that cannot be reached in time have an empty VO: dropped.
    - ``pz_buffer``: a buffer against the discretisation and the neighbours' own manoeuvres, a
      larger planning sphere, but never so large that A is 'inside' it while outside the real
      one (the VO would degenerate to a half-space): at most 90 % of the gap left.
    - Reciprocal (RVO): the apex at (V_A + V_B)/2, each of two cooperative vehicles taking half
      the avoidance; a neighbour that does not avoid keeps the apex V_B.
    - The virtual sphere (3.1.6) is sized for every speed up to v_max.
    - A cone that no velocity within the speed limit reaches can neither hold an answer nor
      constrain one: left out of every formulation (and of the exact check, equivalently).
    - A prism whose top h_pz reaches the ceiling z_max cannot be flown over: it is planned as
      reaching far above (else a climb 'over' it, allowed one step at a time by the altitude
      rows, ends squeezed between the ceiling and the prism: sweep 'lagged' encounter 647).
    """
    rows = cone_rows(p, v_now, nbrs, bounds, cfg)
    return vos_of(
        p, aimed(v_pref, bounds), rows, pyramids_in_reach(p, prisms, bounds, cfg), bounds, cfg
    )


@jit
def aimed(v_pref: np.ndarray, bounds: Bounds) -> np.ndarray:
    """The preferred velocity clamped to v_max (beyond reach it is aimed at the reachable one)."""
    speed = np.sqrt(v_pref[0] ** 2 + v_pref[1] ** 2 + v_pref[2] ** 2)
    pref = np.empty(3)
    for k in range(3):
        pref[k] = v_pref[k] * (bounds.v_max / speed) if speed > bounds.v_max else v_pref[k]
    return pref


@jit
def cone_rows(
    p: np.ndarray, v_now: np.ndarray, nbrs: np.ndarray, bounds: Bounds, cfg: Config
) -> np.ndarray:
    """Each neighbour's row for ``build_cones`` (k, 7): p_B, apex, r_pz, of the neighbours
    ``build_vos`` keeps before the cones' geometry (the horizon; the buffer and the reciprocal
    apex applied)."""
    rows, n = np.empty((nbrs.shape[0], 7)), 0
    for i in range(nbrs.shape[0]):
        d = np.sqrt((nbrs[i, 0] - p[0]) ** 2 + (nbrs[i, 1] - p[1]) ** 2 + (nbrs[i, 2] - p[2]) ** 2)
        r_pz, v_b = nbrs[i, 6], np.sqrt(nbrs[i, 3] ** 2 + nbrs[i, 4] ** 2 + nbrs[i, 5] ** 2)
        if cfg.horizon >= 0.0 and d - r_pz > cfg.horizon * (bounds.v_max + v_b):
            continue
        cooperative = cfg.reciprocal and nbrs[i, 7] > 0.0
        for k in range(3):
            rows[n, k] = nbrs[i, k]
            rows[n, 3 + k] = 0.5 * (nbrs[i, 3 + k] + v_now[k]) if cooperative else nbrs[i, 3 + k]
        rows[n, 6] = (
            r_pz + min(cfg.pz_buffer, BUFFER_GAP_SHARE * (d - r_pz))
            if cfg.pz_buffer > 0.0 and d > r_pz
            else r_pz
        )
        n += 1
    return rows[:n]


@jit
def pyramids_in_reach(p: np.ndarray, prisms: np.ndarray, bounds: Bounds, cfg: Config) -> VOPyramids:
    """The VO pyramids of the prisms within reach (all without a horizon); a prism reaching the
    ceiling planned as reaching far above it."""
    near, m = np.empty((prisms.shape[0], 4)), 0
    for j in range(prisms.shape[0]):
        dist = np.sqrt((prisms[j, 0] - p[0]) ** 2 + (prisms[j, 1] - p[1]) ** 2)
        if cfg.horizon < 0.0 or dist - prisms[j, 2] / np.sqrt(2.0) <= cfg.horizon * bounds.v_max:
            for k in range(4):
                near[m, k] = prisms[j, k]
            if prisms[j, 3] >= bounds.z_max:
                near[m, 3] = max(prisms[j, 3], p[2]) + OVER_THE_CEILING
            m += 1
    return build_pyramids(p, near[:m])


@jit
def vos_of(
    p: np.ndarray,
    pref: np.ndarray,
    rows: np.ndarray,
    pyramids: VOPyramids,
    bounds: Bounds,
    cfg: Config,
) -> VOs:
    """``build_vos`` from its parts: the cones of ``cone_rows`` (eqs 1, 2, 6), less those no
    velocity within v_max reaches (their rows are moved within ``rows``)."""
    reach = bounds.v_max if cfg.corrections.virtual_sphere else NO_VIRTUAL_SPHERE
    n = rows.shape[0]
    cones = build_cones(p, rows[:, 0:3], rows[:, 3:6], rows[:, 6], reach, TAU_MIN)
    kept = 0
    for i in range(n):  # the kept rows first, in place (rows is this decision's own)
        if min_speed(cones, i) <= bounds.v_max + 1e-6:
            for k in range(7):
                rows[kept, k] = rows[i, k]
            kept += 1
    if kept < n:
        cones = build_cones(p, rows[:kept, 0:3], rows[:kept, 3:6], rows[:kept, 6], reach, TAU_MIN)
    return VOs(cones, pyramids, pref)


@jit
def pref_clear(
    p: np.ndarray, rows: np.ndarray, pyramids: VOPyramids, pref: np.ndarray, horizon: float
) -> bool:
    """Whether A is inside no zone and ``pref`` lies in no VO, from each neighbour's row of
    ``cone_rows`` before the cones' geometry: ``build_cones``' d_oi and ``in_cone``'s test on
    the same numbers (``offset``, ``heads_into``), so the same answer as the exact check on the
    cones (``vos_of`` may leave out cones that no velocity within v_max reaches; the aimed
    ``pref`` lies in none of them)."""
    rel = np.empty(3)
    for i in range(rows.shape[0]):
        if offset(rows[i, 0:3], p, rel) <= rows[i, 6]:  # inside: d_oi <= r_pz
            return False
        if heads_into(rows[i, 3:6], rel, rows[i, 6], pref, horizon, 0.0):
            return False
    for j in range(pyramids.L_pz.shape[0]):
        if pyramids.inside[j] or in_pyramid(pyramids, j, pref, horizon):
            return False
    return True


@entry
def vz_range(z: float, bounds: Bounds) -> tuple[float, float]:
    """Vertical speeds that keep z + v_z dt within [z_min, z_max]; out of bounds already: head
    back at full speed."""
    lo = max((bounds.z_min - z) / bounds.dt, -bounds.v_max)
    hi = min((bounds.z_max - z) / bounds.dt, bounds.v_max)
    if lo > hi:
        lo = hi = bounds.v_max if z < bounds.z_min else -bounds.v_max
    return lo, hi


@entry
def limit_rows(
    p: np.ndarray, v_now: np.ndarray, nbrs: np.ndarray, bounds: Bounds, cfg: Config
) -> tuple[np.ndarray, np.ndarray]:
    """The altitude bound, the acceleration box |v - v_now| <= a·dt per axis (with an
    acceleration limit) and, with ``closing_guard``, one row per cooperative neighbour whose
    zone could be reached within dt (``_closing_row``), as G v <= h."""
    rows = 2 if np.isnan(bounds.acceleration) else 8
    guards = 0
    if cfg.closing_guard:
        for i in range(nbrs.shape[0]):
            if _closing_row(p, v_now, nbrs, i, bounds)[3] < np.inf:
                guards += 1
    G, h = np.zeros((rows + guards, 3)), np.empty(rows + guards)
    lo, hi = vz_range(p[2], bounds)
    G[0, 2], h[0], G[1, 2], h[1] = 1.0, hi, -1.0, -lo
    if rows == 8:
        dv = bounds.acceleration * bounds.dt
        for k in range(3):
            G[2 + 2 * k, k], h[2 + 2 * k] = 1.0, v_now[k] + dv
            G[3 + 2 * k, k], h[3 + 2 * k] = -1.0, dv - v_now[k]
    for i in range(nbrs.shape[0] if guards else 0):
        ux, uy, uz, c = _closing_row(p, v_now, nbrs, i, bounds)
        if c < np.inf:
            G[rows, 0], G[rows, 1], G[rows, 2], h[rows] = ux, uy, uz, c
            rows += 1
    return G, h


@inline
def _closing_row(
    p: np.ndarray, v_now: np.ndarray, nbrs: np.ndarray, i: int, bounds: Bounds
) -> tuple[float, float, float, float]:
    """The closing guard's row u·v <= c for neighbour i, u the unit vector towards it; c = inf
    when the row constrains nothing.

    c is half the gap (d - r_pz, 0 inside) per dt: B runs the same rule, so the pair closes by
    at most the gap within the step, whatever each chooses. That is what the VO cannot promise
    when both change velocity at once (README: safety in simulation). No row for a vehicle
    that does not avoid (its VO is exact: it keeps its velocity) or when c >= v_max. With an
    acceleration limit c is raised to u·v_brake, v_brake the point of the box |v - v_now| <= a·dt
    nearest hovering, so that the box and every guard row share it (the promise then holds for
    the pairs whose rows were not raised; formulations/plane_qp.md)."""
    dx, dy, dz = nbrs[i, 0] - p[0], nbrs[i, 1] - p[1], nbrs[i, 2] - p[2]
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    if not (nbrs[i, 7] > 0.0 and d > 0.0):
        return 0.0, 0.0, 0.0, np.inf
    ux, uy, uz = dx / d, dy / d, dz / d
    c = 0.5 * max(d - nbrs[i, 6], 0.0) / bounds.dt
    if not np.isnan(bounds.acceleration):
        dv = bounds.acceleration * bounds.dt
        brake = ux * _brake(v_now[0], dv) + uy * _brake(v_now[1], dv) + uz * _brake(v_now[2], dv)
        c = max(c, brake)
    return ux, uy, uz, (c if c < bounds.v_max else np.inf)


@inline
def _brake(v: float, dv: float) -> float:
    """The component in [v - dv, v + dv] nearest 0."""
    return min(max(0.0, v - dv), v + dv)


@inline
def within_limits(v: np.ndarray, G: np.ndarray, h: np.ndarray, bounds: Bounds) -> bool:
    """Speed in [v_min, v_max] and G v <= h, each within LIMIT_TOL."""
    speed = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    if not (bounds.v_min - LIMIT_TOL <= speed <= bounds.v_max + LIMIT_TOL):
        return False
    for j in range(G.shape[0]):
        if G[j, 0] * v[0] + G[j, 1] * v[1] + G[j, 2] * v[2] > h[j] + LIMIT_TOL:
            return False
    return True


@inline
def containing(vos: VOs, v: np.ndarray, horizon: float, out: np.ndarray) -> bool:
    """Which VOs (cones first) contain v, by the exact 3D membership, into ``out``; whether any."""
    n, any_in = vos.cones.d_oi.shape[0], False
    for i in range(n):
        out[i] = in_cone(vos.cones, i, v, horizon, 0.0)
        any_in |= out[i]
    for j in range(vos.pyramids.L_pz.shape[0]):
        out[n + j] = in_pyramid(vos.pyramids, j, v, horizon)
        any_in |= out[n + j]
    return any_in


@inline
def _zone_time(vos: VOs, k: int, v: np.ndarray) -> float:
    """When zone k (cones first) would be entered at velocity v (inf: never; 0: inside and
    closing)."""
    c, n = vos.cones, vos.cones.d_oi.shape[0]
    if k >= n:
        py, j = vos.pyramids, k - n
        if py.inside[j]:
            h = py.frame[j, 0]
            return 0.0 if h[0] * v[0] + h[1] * v[1] + h[2] * v[2] > 0 else np.inf
        return entry_time(py, j, v)
    _, _, pu = closest_approach(c, k, v, NO_HORIZON)
    if c.inside[k]:
        return 0.0 if pu > 0 else np.inf
    u0, u1, u2 = v[0] - c.apex[k, 0], v[1] - c.apex[k, 1], v[2] - c.apex[k, 2]
    uu = u0 * u0 + u1 * u1 + u2 * u2
    disc = pu * pu - uu * (c.d_oi[k] ** 2 - c.r_pz[k] ** 2)
    if disc > 0 and pu > 0 and uu > 0:
        return max((pu - np.sqrt(disc)) / uu, 0.0)
    return np.inf


@inline
def zone_time_bound(vos: VOs, k: int, c: np.ndarray, rho: float) -> float:
    """A time by which zone k (a cone: k < the cone count) is entered, as ``_zone_time``
    computes it, at every velocity within ``rho`` of ``c``; inf when none is known (A inside
    the zone, the ball reaching the apex or not wholly closing in).

    ``_zone_time``'s root is Q / (pu + sqrt(pu^2 - |u|^2 Q)), Q = d_oi^2 - r_pz^2, which falls
    as pu = rel·u and the root's argument rise: over the ball pu >= pu_c - |rel| rho and
    |u| <= |u_c| + rho bound both from below. Widened far beyond the rounding of the root as
    ``_zone_time`` computes it, so that every velocity of the ball is computed to enter before
    this time, not only in exact arithmetic."""
    cones = vos.cones
    if cones.inside[k]:
        return np.inf
    a, rel = cones.apex[k], cones.rel[k]
    u0, u1, u2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    nu = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    nrel = np.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2)
    pu_lo = rel[0] * u0 + rel[1] * u1 + rel[2] * u2 - nrel * rho
    pu_hi, Q = nrel * (nu + rho), cones.d_oi[k] ** 2 - cones.r_pz[k] ** 2
    disc_lo = pu_lo * pu_lo - (nu + rho) ** 2 * Q
    # pu as computed is off by a few ulp of pu_hi (its terms cancel), pu^2 - |u|^2 Q by a few
    # ulp of pu_hi^2: both must stay positive as computed at every velocity of the ball
    if not (nu > rho and Q > 0.0 and pu_lo > 1e-13 * pu_hi and disc_lo > 1e-13 * pu_hi**2):
        return np.inf  # NaN fails too
    t, uu_lo = Q / (pu_lo + np.sqrt(disc_lo)), (nu - rho) ** 2
    # the root's rounding: that of pu over |u|^2, and of the square root (the argument's
    # over sqrt(disc_lo): large near a tangent) over |u|^2
    return t + 1e-9 * (t + pu_hi / uu_lo) + 1e-12 * pu_hi * pu_hi / np.sqrt(disc_lo) / uu_lo


@inline
def time_to_intrusion(vos: VOs, v: np.ndarray, floor: float, hint: np.ndarray) -> float:
    """The earliest time (s) any protected zone would be entered at velocity v (inf: never; 0:
    inside and closing). The least-bad velocity maximises it. Once the time is known to be
    below ``floor`` it is returned at once (``floor`` -1: always the earliest time), and the
    zone that showed it goes into hint[0], where the next call starts: in a crowd most
    velocities are beaten by the same zone."""
    count, t = vos.cones.d_oi.shape[0] + vos.pyramids.L_pz.shape[0], np.inf
    k = hint[0]
    for _ in range(count):  # k wraps round by hand: a modulo per velocity costs more
        t = min(t, _zone_time(vos, k, v))
        if t < floor or t == 0.0:
            hint[0] = k
            return t
        k = k + 1 if k + 1 < count else 0
    return t


@inline
def closing_rate(vos: VOs, v: np.ndarray) -> float:
    """The fastest rate (m/s) at which velocity v closes on a zone A is inside: on a neighbour's
    centre (the relative velocity along the line of centres, as ``_zone_time`` judges closing)
    or on an obstacle's prism (towards it, horizontally); 0 when it closes on none."""
    c, worst = vos.cones, 0.0
    for k in range(c.d_oi.shape[0]):
        if c.inside[k]:
            _, _, pu = closest_approach(c, k, v, NO_HORIZON)
            worst = max(worst, pu / max(c.d_oi[k], 1e-12))
    py = vos.pyramids
    for j in range(py.L_pz.shape[0]):
        if py.inside[j]:
            h = py.frame[j, 0]
            worst = max(worst, h[0] * v[0] + h[1] * v[1] + h[2] * v[2])
    return worst


@entry
def _closing_rates(vos: VOs, v: np.ndarray) -> np.ndarray:
    out = np.empty(v.shape[0])
    for k in range(v.shape[0]):
        out[k] = closing_rate(vos, v[k])
    return out


@entry
def _times_to_intrusion(vos: VOs, v: np.ndarray) -> np.ndarray:
    out, hint = np.empty(v.shape[0]), np.zeros(1, dtype=np.int64)
    for k in range(v.shape[0]):
        out[k] = time_to_intrusion(vos, v[k], -1.0, hint)
    return out


@entry
def _all_within(v: np.ndarray, G: np.ndarray, h: np.ndarray, bounds: Bounds) -> np.ndarray:
    out = np.empty(v.shape[0], dtype=np.bool_)
    for k in range(v.shape[0]):
        out[k] = within_limits(v[k], G, h, bounds)
    return out


@jit
def decision_planes(vos: VOs, v_now: np.ndarray, cfg: Config) -> AvoidancePlanes:
    """Planes every ``plane_step_deg`` about the preferred direction (or the current heading, or
    world x when both are zero)."""
    use_pref = vos.v_pref[0] ** 2 + vos.v_pref[1] ** 2 + vos.v_pref[2] ** 2 >= 1e-18
    use_now = v_now[0] ** 2 + v_now[1] ** 2 + v_now[2] ** 2 > 1e-18
    direction = np.zeros(3)
    for k in range(3):
        direction[k] = (
            vos.v_pref[k] if use_pref else (v_now[k] if use_now else (1.0 if k == 0 else 0.0))
        )
    return build_planes(direction, cfg.phi, cfg.cos_phi, cfg.sin_phi)


@entry
def py_pref_clear(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> bool:
    """``pref_clear`` on the parts ``build_vos`` starts from, for Python callers (tests)."""
    rows, pyramids = (
        cone_rows(p, v_now, nbrs, bounds, cfg),
        pyramids_in_reach(p, prisms, bounds, cfg),
    )
    return pref_clear(p, rows, pyramids, aimed(v_pref, bounds), cfg.horizon)


@entry
def py_build_vos(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> VOs:
    """``build_vos`` for Python callers (the kernel calls its parts: ``decide_one``)."""
    return build_vos(p, v_now, v_pref, nbrs, prisms, bounds, cfg)


@entry
def py_decision_planes(vos: VOs, v_now: np.ndarray, cfg: Config) -> AvoidancePlanes:
    """``decision_planes`` for Python callers (compiled code calls ``decision_planes``: no Python
    wrapper)."""
    return decision_planes(vos, v_now, cfg)


# ------------------------------------------------------------------------------- Python side


def neighbor_rows(neighbors: Sequence[Neighbor]) -> np.ndarray:
    """(n, 8): position, velocity, r_pz, cooperative (1/0) of each neighbour (one flat pass:
    numpy builds a 2D array from nested tuples much more slowly)."""
    flat = itertools.chain.from_iterable([nb.row for nb in neighbors])
    return np.fromiter(flat, dtype=float, count=8 * len(neighbors)).reshape(-1, 8)


@dataclass
class Encounter:
    """One decision's inputs for the Python formulations, with the VO shapes built once."""

    position: np.ndarray
    v_now: np.ndarray
    vos: VOs
    limits: Limits
    dt: float
    options: Options
    nbrs: np.ndarray  # (n, 8) ``neighbor_rows``: the closing guard's rows need them

    @property
    def v_pref(self) -> np.ndarray:
        """The preferred velocity, clamped to v_max."""
        return self.vos.v_pref

    @property
    def cones(self) -> VOCones:
        return self.vos.cones

    @property
    def pyramids(self) -> VOPyramids:
        return self.vos.pyramids

    @cached_property
    def bounds(self) -> Bounds:
        return Bounds.of(self.limits, self.dt)

    @cached_property
    def inside(self) -> np.ndarray:
        """(n + m,) whether A is inside each zone (cones first, then pyramids)."""
        return np.concatenate([self.cones.inside, self.pyramids.inside])

    @cached_property
    def inside_any(self) -> bool:
        return bool(self.inside.any())

    def vz_range(self) -> tuple[float, float]:
        """Vertical speeds that keep z + v_z dt within [z_min, z_max]."""
        return vz_range(float(self.position[2]), self.bounds)

    @cached_property
    def _linear_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        G, h = limit_rows(self.position, self.v_now, self.nbrs, self.bounds, self.options.config)
        G.setflags(write=False)
        h.setflags(write=False)
        return G, h

    def linear_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Altitude and acceleration limits as G v <= h in 3D (computed once; read-only)."""
        return self._linear_bounds

    def within_limits(self, v: np.ndarray) -> np.ndarray:
        """(M,) whether each velocity respects speed, altitude and acceleration limits."""
        G, h = self._linear_bounds
        return _all_within(
            np.ascontiguousarray(np.atleast_2d(np.asarray(v, dtype=float))), G, h, self.bounds
        )

    def containing(self, v: np.ndarray) -> np.ndarray:
        """(n + m, M): which VOs (cones first, then pyramids) contain each velocity, by the
        exact 3D membership."""
        return in_vos(self.cones, self.pyramids, v, horizon=self.options.horizon)

    @cached_property
    def pref_in(self) -> np.ndarray:
        """(n + m,) which VOs contain the preferred velocity (computed once)."""
        return self.containing(self.v_pref)[:, 0]

    def unsafe(self, v: np.ndarray) -> np.ndarray:
        """(M,) whether each velocity lies in some VO (exact 3D membership)."""
        return np.any(self.containing(v), axis=0)

    def time_to_intrusion(self, v: np.ndarray) -> np.ndarray:
        """(M,) the earliest time any protected zone would be entered (inf: never; 0: inside
        and closing)."""
        return _times_to_intrusion(
            self.vos, np.ascontiguousarray(np.atleast_2d(np.asarray(v, dtype=float)))
        )

    def closing_rate(self, v: np.ndarray) -> np.ndarray:
        """(M,) the fastest rate at which each velocity closes on a zone A is inside."""
        return _closing_rates(
            self.vos, np.ascontiguousarray(np.atleast_2d(np.asarray(v, dtype=float)))
        )

    def deviation(self, v: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.atleast_2d(v) - self.v_pref, axis=1)


def prepare(
    own: AgentState,
    v_pref: np.ndarray,
    neighbors: Sequence[Neighbor],
    obstacles: Sequence[Cylinder | Box],
    limits: Limits,
    dt: float,
    options: Options,
) -> Encounter:
    """Build the VO cones and pyramids of one decision (``build_vos``)."""
    bounds, nbrs = Bounds.of(limits, dt), neighbor_rows(neighbors)
    vos = py_build_vos(
        np.asarray(own.position, dtype=float),
        np.asarray(own.velocity, dtype=float),
        np.asarray(v_pref, dtype=float),
        nbrs,
        prism_rows(obstacles),
        bounds,
        options.config,
    )
    return Encounter(
        position=own.position,
        v_now=own.velocity,
        vos=vos,
        limits=limits,
        dt=float(dt),
        options=options,
        nbrs=nbrs,
    )


@dataclass
class Outcome:
    """A formulation's answer before the selector times it."""

    velocity: np.ndarray
    status: Status
    plane: float | None = None  # phi (rad) of the plane the velocity was chosen on
    info: dict = field(default_factory=dict)
