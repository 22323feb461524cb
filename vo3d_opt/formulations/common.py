"""What every formulation shares: the options, the VOs of one decision (built by the same
compiled parts for the compiled decision and for the Python formulations alike: ``build_vos``),
the limits as linear constraints, the exact safety check and the time to the first intrusion.

The compiled core (``vo3d_opt._core``; its algorithm reads in ``vo3d_opt/algorithm/``) receives
the options as a ``Config`` (``Options.config``) and the limits as ``Bounds``; the Python
formulations wrap the same values in an ``Encounter``.
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

import vo3d_opt._core as _core

from ..geometry import (
    CORRECTIONS,
    AvoidancePlanes,
    Corrections,
    VOCones,
    VOPyramids,
    default_phis,
    in_vos,
)
from ..geometry.membership import NO_HORIZON
from ..geometry.pyramid import prism_rows
from ..geometry.sections import generator_angles
from ..solvers import NLP, QP, Result
from ..status import Status
from ..types import AgentState, Box, Cylinder, Limits, Model, Neighbor

#: Tolerance (m/s) on the speed and altitude limits when checking a candidate (the core's).
LIMIT_TOL: float = _core.LIMIT_TOL
#: With ``pz_buffer``, the planning sphere grows by at most this share of the remaining gap.
BUFFER_GAP_SHARE = 0.9
#: Cap on the time to intrusion (s) when comparing least-bad candidates ("never").
NEVER: float = _core.NEVER
#: A prism whose top reaches the ceiling is planned this much (m) above the vehicle and the
#: ceiling: no velocity's ray passes over it.
OVER_THE_CEILING = 1e3

Solve = Callable[[QP], Result]
SolveNLP = Callable[[NLP], Result]

_Deg = Annotated[float, Field(gt=0, le=180, allow_inf_nan=False)]


#: The options as the compiled core reads them (``Options.config``): a ``vo3d_opt._core.Config``
#: of named fields, set one by one (``Options.kernel_fields``).
Config = _core.Config


class Bounds(NamedTuple):
    """The limits of one decision as the compiled core reads them."""

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
    # s, the obstacles' VO pyramids' own horizon (RVO2-3D's timeHorizonObst); None: infinite
    obstacle_horizon: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
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
    # planning spheres or prisms, closing on one whichever way it turns): the one that closes
    # slowest on the zones A is inside, not the one nearest the preferred velocity
    # (fallback.least_bad): the nearest one tends to fly straight on into the zone it is in
    least_bad_escape: StrictBool = True
    # the fallbacks' grid (when no QP answer is safe) with at least the default one's speeds
    # and headings (FINE_SPEED_LEVELS, FINE_HEADING_STEP: denser, though it need not hold every
    # point of a coarser grid) in a decision with something that does not avoid: an obstacle's
    # VO pyramid in reach or any non-cooperative neighbour (fallback.has_hazard, grid_of). A
    # no-op with the default grid; with a coarse one (safe's, fast's) it is what keeps
    # obstacles' zones clear: under an acceleration limit few points of an 8 x 3 grid can be
    # reached, and an obstacle does not take its share of the avoidance
    fine_fallback: StrictBool = True
    # the fallbacks' grid's headings (degrees) and speeds; None: the sampled grid's
    fallback_heading_step_deg: _Deg | None = None
    fallback_speed_levels: Annotated[int, Field(ge=2, strict=True)] | None = None
    # in a decision with something that does not avoid (has_hazard), at least the default
    # planes and tangent samples (fine_options): an obstacle takes no share of the avoidance,
    # and under a lag the velocity that clears it may lie between coarse planes
    fine_planes: StrictBool = True

    @cached_property
    def fine_options(self) -> Options | None:
        """These options on at least the default planes and tangent samples, for a decision
        with something that does not avoid (``fine_planes``); None when off, or when these
        planes are as fine already."""
        step = min(self.plane_step_deg, FINE_PLANE_STEP_DEG)
        samples = max(self.qp_samples, FINE_QP_SAMPLES)
        if not self.fine_planes or (step, samples) == (self.plane_step_deg, self.qp_samples):
            return None
        fields = {name: getattr(self, name) for name in type(self).model_fields}
        return type(self)(**{**fields, "plane_step_deg": step, "qp_samples": samples})

    def kernel_fields(self) -> dict[str, object]:
        """The compiled core's ``Config`` fields by name: every option the core has a field of
        the same name for, as it is, save those it reads in another form (the horizon,
        NO_HORIZON for none; the corrections' flags); and those derived from options (the
        planes' and the generators' angles with numpy's cosines and sines; the grids' heading
        steps in rad; the fallbacks' grid as the sampled one where it has none of its own)."""
        t, phi = generator_angles(self.qp_samples), default_phis(self.plane_step_deg)
        corrections = _core.Corrections()
        for name, on in Corrections.of(self.corrections)._asdict().items():
            setattr(corrections, name, on)
        derived = {
            "horizon": NO_HORIZON if self.horizon is None else self.horizon,
            "obstacle_horizon": (
                NO_HORIZON if self.obstacle_horizon is None else self.obstacle_horizon
            ),
            "corrections": corrections,
            "phi": phi,
            "cos_phi": np.cos(phi),
            "sin_phi": np.sin(phi),
            "t": t,
            "cos_t": np.cos(t),
            "sin_t": np.sin(t),
            "heading_step": math.radians(self.heading_step_deg),
            "fallback_heading_step": math.radians(
                self.heading_step_deg
                if self.fallback_heading_step_deg is None
                else self.fallback_heading_step_deg
            ),
            "fallback_speed_levels": (
                self.speed_levels
                if self.fallback_speed_levels is None
                else self.fallback_speed_levels
            ),
        }
        same = {name: getattr(self, name) for name in KERNEL_OPTIONS if name not in derived}
        return {**same, **derived}

    @cached_property
    def config(self) -> Config:
        """The options as the compiled core reads them: a ``Config`` set field by field (shared
        by every decision with these options: not to be changed), with ``fine_options``'s as
        its ``fine`` where there are any."""
        config = Config()
        for name, value in self.kernel_fields().items():
            setattr(config, name, value)
        if self.fine_options is not None:
            config.fine = self.fine_options.config
        return config


#: The options the compiled core has a field of the same name for.
KERNEL_OPTIONS = tuple(name for name in Options.model_fields if hasattr(Config, name))
#: The planes and tangent samples of a decision with something that does not avoid
#: (``fine_planes``): at least the defaults'.
FINE_PLANE_STEP_DEG: float = Options.model_fields["plane_step_deg"].default
FINE_QP_SAMPLES: int = Options.model_fields["qp_samples"].default

#: The fallbacks' grid in a decision with something that does not avoid (``fine_fallback``):
#: at least the default grid's speeds and headings (rad); the core's (tests hold them to the
#: defaults of ``Options``).
FINE_SPEED_LEVELS: int = _core.FINE_SPEED_LEVELS
FINE_HEADING_STEP: float = _core.FINE_HEADING_STEP


# ------------------------------------------------------------------------------- the core


def py_build_vos(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> VOs:
    """The VOs of one decision (compiled: ``build_vos``). ``nbrs`` (n, 8): position, velocity,
    r_pz, cooperative (1/0); ``prisms`` (m, 6): ``prism_rows`` (or (m, 4): no roofs).

    - The preferred velocity beyond reach is aimed at the reachable one (clamped to v_max).
    - With a horizon, zones that cannot be reached in time have an empty VO: dropped.
    - ``pz_buffer``: a buffer against the discretisation and the neighbours' own manoeuvres, a
      larger planning sphere, but never so large that A is 'inside' it while outside the real
      one (the VO would degenerate to a half-space): at most 90 % of the gap left. In the
      inner half of a cooperative neighbour's buffer the apex moves away from it, so that
      holding the gap is inside the VO (``BUFFER_OPENING`` in algorithm/vo.hpp).
    - Reciprocal (RVO): the apex at (V_A + V_B)/2, each of two cooperative vehicles taking half
      the avoidance; a neighbour that does not avoid keeps the apex V_B.
    - The virtual sphere (3.1.6) is sized for every speed up to v_max.
    - A cone that no velocity within the speed limit reaches can neither hold an answer nor
      constrain one: left out of every formulation (and of the exact check, equivalently).
    - A prism whose top h_pz reaches the ceiling z_max cannot be flown over: it is planned as
      reaching far above (else a climb 'over' it, allowed one step at a time by the altitude
      rows, ends squeezed between the ceiling and the prism, with no way on or back).
    """
    cones, pyramids, pref = _core.build_vos(p, v_now, v_pref, nbrs, prisms, bounds, cfg)
    return VOs(VOCones(*cones), VOPyramids(*pyramids), pref)


def py_pref_clear(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: Bounds,
    cfg: Config,
) -> bool:
    """Whether A is inside no zone and the aimed preferred velocity lies in no VO, judged from
    the neighbours' rows before the cones' geometry (compiled: ``pref_clear``), as the decision
    does before it builds the cones."""
    return bool(_core.pref_clear(p, v_now, v_pref, nbrs, prisms, bounds, cfg))


def py_decision_planes(vos: VOs, v_now: np.ndarray, cfg: Config) -> AvoidancePlanes:
    """Planes every ``plane_step_deg`` about the preferred direction (or the current heading, or
    world x when both are zero)."""
    return AvoidancePlanes(*_core.decision_planes(vos, v_now, cfg))


def vz_range(z: float, bounds: Bounds) -> tuple[float, float]:
    """Vertical speeds that keep z + v_z dt within [z_min, z_max] and, with an acceleration
    limit a, approach an edge d away at no more than the s with s dt + s^2 / (2 a) = d (room to
    brake); out of the band already: back towards it, no faster than the far edge allows (v_max
    without an acceleration limit)."""
    return _core.vz_range(float(z), bounds)


def limit_rows(
    p: np.ndarray, v_now: np.ndarray, nbrs: np.ndarray, bounds: Bounds, cfg: Config
) -> tuple[np.ndarray, np.ndarray]:
    """The altitude bound, the acceleration box |v - v_now| <= a·dt per axis (with an
    acceleration limit) and, with ``closing_guard``, one row per cooperative neighbour whose
    zone could be reached within dt, as G v <= h.

    The guard row of neighbour B is u·v <= c, u the unit vector towards it, c half the gap
    (d - r_pz, 0 inside) per dt: B runs the same rule, so the pair closes by at most the gap
    within the step, whatever each chooses. No row for a vehicle that does not avoid (its VO
    is exact: it keeps its velocity) or when c >= v_max. With an acceleration limit c is
    raised to u·v_brake, v_brake the point of the box nearest hovering, so that the box and
    every guard row share it (formulations/plane_qp.md)."""
    return _core.limit_rows(p, v_now, nbrs, bounds, cfg)


def _zone_time(vos: VOs, k: int, v: np.ndarray) -> float:
    """When zone k (cones first) would be entered at velocity v (inf: never; 0: inside and
    closing)."""
    return float(_core.zone_times(vos, int(k), np.asarray(v, dtype=float).reshape(1, 3))[0])


def zone_time_bound(vos: VOs, k: int, c: np.ndarray, rho: float) -> float:
    """A time by which zone k (a cone) is entered, as ``_zone_time`` computes it, at every
    velocity within ``rho`` of ``c``; inf when none is known (A inside the zone, the ball
    reaching the apex or not wholly closing in). Widened far beyond the rounding of the root
    as ``_zone_time`` computes it."""
    return float(_core.zone_time_bound(vos, int(k), np.asarray(c, dtype=float), float(rho)))


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
        """Vertical speeds within the altitude band and its braking room (``vz_range``)."""
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

    @cached_property
    def _qp_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        G, h = self._linear_bounds
        Ge, he = _core.escape_rows(self.vos, float(self.options.margin))
        G, h = np.vstack((G, Ge)), np.concatenate((h, he))
        G.setflags(write=False)
        h.setflags(write=False)
        return G, h

    def qp_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The QPs' rows G v <= h: ``linear_bounds`` and, inside a prism under its top, the
        climb its escape needs besides the prism's own row (``qp_limit_rows`` in
        algorithm/limits.hpp); not the fallbacks' limits."""
        return self._qp_bounds

    def within_limits(self, v: np.ndarray) -> np.ndarray:
        """(M,) whether each velocity respects speed, altitude and acceleration limits."""
        G, h = self._linear_bounds
        return _core.all_within(
            np.ascontiguousarray(np.atleast_2d(np.asarray(v, dtype=float))), G, h, self.bounds
        )

    def containing(self, v: np.ndarray) -> np.ndarray:
        """(n + m, M): which VOs (cones first, then pyramids) contain each velocity, by the
        exact 3D membership."""
        return in_vos(
            self.cones,
            self.pyramids,
            v,
            horizon=self.options.horizon,
            obstacle_horizon=self.options.obstacle_horizon,
        )

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
        return _core.times_to_intrusion(
            self.vos, np.ascontiguousarray(np.atleast_2d(np.asarray(v, dtype=float)))
        )

    def closing_rate(self, v: np.ndarray) -> np.ndarray:
        """(M,) the fastest rate at which each velocity closes on a zone A is inside."""
        return _core.closing_rates(
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
    """Build the VO cones and pyramids of one decision (``build_vos``); with something that
    does not avoid, the decision goes on with ``options.fine_options`` where there are any."""
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
        options=planning_options(options, vos, nbrs),
        nbrs=nbrs,
    )


def planning_options(options: Options, vos: VOs, nbrs: np.ndarray) -> Options:
    """The options a decision plans with once its VOs are built (they do not depend on the
    planes): ``options.fine_options`` with something that does not avoid (``has_hazard``)
    where there are any, else ``options``."""
    if options.fine_options is not None and _core.has_hazard(vos, nbrs):
        return options.fine_options
    return options


@dataclass
class Outcome:
    """A formulation's answer before the selector times it."""

    velocity: np.ndarray
    status: Status
    plane: float | None = None  # phi (rad) of the plane the velocity was chosen on
    info: dict = field(default_factory=dict)
