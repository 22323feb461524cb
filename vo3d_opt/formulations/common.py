"""What every formulation shares: the prepared encounter (VO cones and pyramids of one decision),
the limits as linear constraints, the exact safety check, and the least-bad fallback."""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, StrictBool

from ..geometry import CORRECTIONS, VOCones, VOPyramids, in_vos, pyramid_entry_time, vo_cones, vo_pyramids
from .._jit import jit
from ..types import AgentState, Box, Cylinder, Limits, Neighbor
from .problem import QP, NLP, Result

#: Tolerance (m/s) on the speed and altitude limits when checking a candidate.
LIMIT_TOL = 1e-6
#: With ``pz_buffer``, the planning sphere grows by at most this share of the remaining gap.
BUFFER_GAP_SHARE = 0.9

Solve = Callable[[QP], Result]
SolveNLP = Callable[[NLP], Result]


_Deg = Annotated[float, Field(gt=0, le=180, allow_inf_nan=False)]


class Options(BaseModel):
    """Formulation options (the selector's keyword arguments), validated: a wrong value raises
    ``ValueError`` (pydantic's ``ValidationError``) naming the option."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    plane_step_deg: _Deg = 10.0  # avoidance planes every this many degrees in [-90, 90]
    heading_step_deg: _Deg = 10.0  # sampled: polar grid, heading resolution in each plane
    speed_levels: Annotated[int, Field(ge=2, strict=True)] = 9  # sampled: speeds v_min..v_max
    polygon_sides: Annotated[int, Field(ge=3, strict=True)] = 24  # inscribed speed polygon
    reciprocal: StrictBool = False  # RVO-style: apex (V_A + V_B)/2 for cooperative neighbours
    horizon: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None  # s; None: infinite
    corrections: frozenset[Literal[tuple(CORRECTIONS)]] | None = None  # None: all six of 3.1
    n_samples: Annotated[int, Field(ge=8, strict=True)] = 72  # generator samples of eq. (12), sampled
    qp_samples: Annotated[int, Field(ge=8, strict=True)] = 36  # the same for plane_qp's tangent points
    pz_buffer: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0  # m; see prepare
    margin: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 1e-3  # m/s; linearised VO
    # half-spaces are pushed out by this much, so that a solver's answer on the boundary
    # (within its tolerance) is still strictly outside the VO


@dataclass
class Encounter:
    """One decision's inputs, with the VO shapes built once."""

    position: np.ndarray
    v_now: np.ndarray
    v_pref: np.ndarray  # clamped to v_max
    cones: VOCones
    pyramids: VOPyramids
    limits: Limits
    dt: float
    options: Options

    @cached_property
    def inside(self) -> np.ndarray:
        """(n + m,) whether A is inside each zone (cones first, then pyramids)."""
        return np.concatenate([self.cones.inside, self.pyramids.inside])

    @cached_property
    def inside_any(self) -> bool:
        return bool(self.inside.any())

    # --- the limits -------------------------------------------------------------------------
    def vz_range(self) -> tuple[float, float]:
        """Vertical speeds that keep z + v_z dt within [z_min, z_max]."""
        z, lim, vmax = self.position[2], self.limits, self.limits.v_max
        lo = (lim.z_min - z) / self.dt
        hi = (lim.z_max - z) / self.dt
        lo, hi = max(lo, -vmax), min(hi, vmax)
        if lo > hi:  # out of bounds already: head back at full speed
            lo = hi = vmax if z < lim.z_min else -vmax
        return lo, hi

    def linear_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Altitude and acceleration limits as G v <= h in 3D (computed once; read-only)."""
        return self._linear_bounds

    @cached_property
    def _linear_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.vz_range()
        G = [np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])]
        h = [hi, -lo]
        if self.limits.acceleration is not None:
            dv = self.limits.acceleration * self.dt
            for k in range(3):
                e = np.zeros(3)
                e[k] = 1.0
                G += [e, -e]
                h += [self.v_now[k] + dv, dv - self.v_now[k]]
        G, h = np.array(G), np.array(h)
        G.setflags(write=False)
        h.setflags(write=False)
        return G, h

    def within_limits(self, v: np.ndarray) -> np.ndarray:
        """(M,) whether each velocity respects speed, altitude and acceleration limits."""
        G, h = self._linear_bounds
        return _within(np.atleast_2d(np.asarray(v, dtype=float)), self.limits.v_min, self.limits.v_max, G, h, LIMIT_TOL)

    # --- safety -----------------------------------------------------------------------------
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
        """(M,) the earliest time any protected zone would be entered (inf: never; 0: inside and
        closing). The least-bad velocity maximises it."""
        v = np.atleast_2d(v)
        t = np.full(len(v), np.inf)
        if len(self.cones):
            c = self.cones
            u = v[None, :, :] - c.apex[:, None, :]
            uu = np.einsum("nmi,nmi->nm", u, u)
            pu = np.einsum("ni,nmi->nm", c.rel, u)
            disc = pu**2 - uu * (c.d_oi**2 - c.r_pz**2)[:, None]
            with np.errstate(invalid="ignore", divide="ignore"):
                t_hit = (pu - np.sqrt(np.maximum(disc, 0.0))) / uu
            t_hit = np.where((disc > 0) & (pu > 0) & (uu > 0), np.maximum(t_hit, 0.0), np.inf)
            t_hit = np.where(c.inside[:, None], np.where(pu > 0, 0.0, np.inf), t_hit)
            t = np.minimum(t, t_hit.min(axis=0))
        if len(self.pyramids):
            t_p = pyramid_entry_time(self.pyramids, v)
            closing = np.einsum("mi,ki->mk", self.pyramids.frame[:, 0, :], v) > 0
            t_p = np.where(self.pyramids.inside[:, None], np.where(closing, 0.0, np.inf), t_p)
            t = np.minimum(t, t_p.min(axis=0))
        return t

    def deviation(self, v: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.atleast_2d(v) - self.v_pref, axis=1)


@jit
def _within(v, v_min, v_max, G, h, tol):
    out = np.empty(v.shape[0], dtype=np.bool_)
    for k in range(v.shape[0]):
        speed = np.sqrt(v[k, 0] ** 2 + v[k, 1] ** 2 + v[k, 2] ** 2)
        ok = v_min - tol <= speed <= v_max + tol
        for j in range(G.shape[0]):
            ok = ok and G[j, 0] * v[k, 0] + G[j, 1] * v[k, 1] + G[j, 2] * v[k, 2] <= h[j] + tol
        out[k] = ok
    return out


def prepare(
    own: AgentState,
    v_pref: np.ndarray,
    neighbors: Sequence[Neighbor],
    obstacles: Sequence[Cylinder | Box],
    limits: Limits,
    dt: float,
    options: Options,
) -> Encounter:
    """Build the VO cones and pyramids of one decision (geometry layer)."""
    p = own.position
    speed = math.hypot(*v_pref.tolist())
    if speed > limits.v_max:  # the goal velocity beyond reach: aim at the reachable one
        v_pref = v_pref * (limits.v_max / speed)
    rows = np.array([nb.row for nb in neighbors], dtype=float).reshape(-1, 8)
    p_B, V_B, r_pz, cooperative = rows[:, :3], rows[:, 3:6], rows[:, 6], rows[:, 7] > 0
    if options.horizon is not None and len(r_pz):
        # With a time horizon, a zone that cannot be reached in time has an empty VO: drop it.
        reach = options.horizon * (limits.v_max + np.linalg.norm(V_B, axis=1))
        keep = np.linalg.norm(p_B - p, axis=1) - r_pz <= reach
        p_B, V_B, r_pz, cooperative = p_B[keep], V_B[keep], r_pz[keep], cooperative[keep]
    if options.horizon is not None:
        obstacles = [o for o in obstacles
                     if np.linalg.norm(o.center - p[:2]) - o.side / np.sqrt(2) <= options.horizon * limits.v_max]
    if options.pz_buffer > 0 and len(r_pz):
        # A buffer against the discretisation and the neighbours' own manoeuvres: plan with a
        # larger sphere, but never so large that A is 'inside' it while outside the real one
        # (the VO would degenerate to a half-space): it takes at most 90 % of the gap left.
        gap = np.linalg.norm(p_B - p, axis=1) - r_pz
        r_pz = np.where(gap > 0, r_pz + np.minimum(options.pz_buffer, BUFFER_GAP_SHARE * gap), r_pz)
    corrections = options.corrections
    # Reciprocal (RVO): the apex at (V_A + V_B)/2, each of two cooperative vehicles taking half
    # the avoidance; a neighbour that does not avoid (cooperative=False) keeps the apex V_B.
    apex = np.where(cooperative[:, None], 0.5 * (V_B + own.velocity), V_B) if options.reciprocal else None
    cones = vo_cones(
        p, p_B, V_B, r_pz, reach=limits.v_max,
        virtual_sphere=corrections is None or "virtual_sphere" in corrections, apex=apex,
    )
    # A cone that no velocity within the speed limit reaches can neither hold an answer nor
    # constrain one: leave it out of every formulation (and of the exact check, equivalently).
    reachable = cones.min_speed() <= limits.v_max + 1e-6
    if not reachable.all():
        cones = cones.subset(reachable)
    return Encounter(
        position=p, v_now=own.velocity, v_pref=np.asarray(v_pref, dtype=float), cones=cones,
        pyramids=vo_pyramids(p, list(obstacles)), limits=limits, dt=dt, options=options,
    )


@dataclass
class Outcome:
    """A formulation's answer before the selector times it."""

    velocity: np.ndarray
    status: str
    plane: float | None = None  # phi (rad) of the plane the velocity was chosen on
    info: dict = field(default_factory=dict)


def first_safe(enc: Encounter, candidates: np.ndarray) -> int | None:
    """Index of the first candidate (in the given order) that is within the limits and outside
    every VO by the exact 3D check, or None."""
    if len(candidates) == 0:
        return None
    ok = enc.within_limits(candidates) & ~enc.unsafe(candidates)
    idx = np.flatnonzero(ok)
    return int(idx[0]) if len(idx) else None


def least_bad(enc: Encounter, candidates: np.ndarray) -> np.ndarray:
    """Among candidates within the limits, the one whose first protected-zone intrusion comes
    latest (ties: nearest the preferred velocity). Falls back to a safe stop-like velocity."""
    extra = np.array([np.zeros(3), enc.v_now])
    c = np.vstack([candidates.reshape(-1, 3), extra]) if len(candidates) else extra
    if enc.limits.acceleration is not None:  # few grid points lie in the reachable box: clip
        dv = enc.limits.acceleration * enc.dt
        c = np.vstack([c, np.clip(c, enc.v_now - dv, enc.v_now + dv)])
    c = c[enc.within_limits(c)]
    if len(c) == 0:  # e.g. v_min > 0 with a zero candidate: the limits' own closest point
        lo, hi = enc.vz_range()
        return np.array([0.0, 0.0, min(max(0.0, lo), hi)])
    t = np.minimum(enc.time_to_intrusion(c), 1e9)
    key = np.lexsort((enc.deviation(c), -t))
    return c[key[0]]
