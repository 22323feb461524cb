"""The scenario format as pydantic models.

A scenario file is a YAML mapping::

    name: paper-case1-ten-uav-crossing     # required, unique among the bundled files
    description: free text                 # optional
    dt: 0.2                                # required: control and integration period, s
    max_time: 150.0                        # required: s; earlier when all are home
    goal_tolerance: 1.0                    # m (default 1.0)
    limits:                                # required; the keys of vo3d_opt.types.Limits
      speed: [0.0, 4.0]                    # m/s: [v_min, v_max], v_min <= v_max, v_max > 0
      altitude: [0.0, 40.0]                # m: [z_min, z_max], z_min < z_max
      acceleration: 3.0                    # optional, m/s², handed to the selector's Limits
    sensing:                               # default: Table 1 of the paper (55 m both)
      vehicle_range: 55.0                  # m, centre to centre
      obstacle_range: 55.0                 # m, to the nearest point of the obstacle
    defaults:                              # default: r_pz 10, radius 0.5, max_speed 4
      r_pz: 10.0                           # protected-zone radius, m
      radius: 0.5                          # physical radius, m (collision counting)
      max_speed: 4.0                       # m/s, the speed bound
      cruise_speed: 2.0                    # m/s, the speed preferred on the way (default max_speed)
    agents:                                # required, at least one
      - {id: u0, start: [40, 0, 20], goal: [-40, 0, 20]}
      - {id: u1, start: [-40, 0, 20], goal: [40, 0, 20], r_pz: 8.0, radius: 0.3, max_speed: 3}
    obstacles:                             # optional; the keys of types.Cylinder / types.Box
      - {type: cylinder, center: [0, 10], radius: 3, height: 30}
      - {type: box, center: [10, -10], size: [6, 6], height: 25, yaw: 0.3}

Further keys (all optional):

* obstacle keys ``L_pz``, ``h_pz``, ``margin`` (those of ``types.Cylinder`` / ``types.Box``: the
  side and height of the protected prism C_pz of the paper's section 4, derived from the size
  plus ``margin`` when omitted) and ``sensed`` (default ``true``). An obstacle with
  ``sensed: false`` is physical (it counts in the metrics and is drawn) but no agent perceives
  it; used to fly the original method's sphere approximation around the real cylinders (paper
  case 3, Fig. 18).
* ``spheres``: a list of ``{center: [x, y, z], radius: r, margin: m, physical: true}``. Each
  sphere is given to the selector as a static ``Neighbor`` (velocity 0, r_pz = radius + margin),
  which is how the original 3D VO of Jenie et al. handles static obstacles. ``physical: false``
  spheres are seen by the agents but ignored by the metrics (they only approximate another
  obstacle). ``margin`` defaults to ``types.PZ_MARGIN``.
* ``velocity_response_tau`` (s): first-order velocity response ``v += (v_cmd - v) * dt / tau``
  (clamped to a full step when ``dt >= tau``); off (ideal kinematics) when omitted.
* ``dynamics``, ``wind``, ``sensing.position_noise`` / ``velocity_noise`` / ``latency`` /
  ``seed`` and the agents' ``avoids`` (the real-world keys; ``vo3d_opt.sim.dynamics``,
  ``vo3d_opt.sim.sensing``); ``dynamics.substep_rate`` (Hz), ``dynamics.command_ramp`` and
  ``dynamics.batched`` (rotorpy) and ``wind.sigma`` / ``wind.altitude`` (Dryden) extend it.
  ``velocity_response_tau`` is an alias of ``dynamics: {model: first_order, tau: ...}`` (not
  both).
* ``safety``: overrides of the margins the simulator derives for those conditions
  (``acceleration``, ``pz_buffer``, ``altitude_margin``, ``obstacle_margin``,
  ``speed_margin``;
  ``vo3d_opt.sim.safety``).
* ``formulation``, ``solver``: defaults for ``vo3d run`` when the command line gives none.
* ``selector_options``: the selector's configuration, ``preset`` (default ``safe``) and any
  field over it, as ``VelocitySelector(preset=..., **fields)`` takes them
  (``vo3d_opt.config``); ``horizon: sensing`` is resolved from ``sensing.vehicle_range``.

One schema: the limits and the obstacles *are* the public types of ``vo3d_opt.types`` (the
obstacle specs subclass them, adding only the scenario's keys), so the file and the Python API
take the same fields, numbers (no booleans or strings for numbers) and checks. Every check
reports at the key it concerns; cross-field checks (:meth:`Scenario._cross_checks`) run once
every key is valid. To add a key: add a field (a nested ``Spec`` for a group of keys) and, when
it depends on other keys, a check in ``_cross_checks``.

A step longer than a sensing range (``max_speed · dt`` above ``sensing.vehicle_range`` with two
or more vehicles, or above ``sensing.obstacle_range`` with obstacles or spheres) is rejected:
whatever appears at the edge of the range is passed before the next decision. A step longer
than an agent's protected-zone radius is allowed but reported by :meth:`Scenario.warnings`
(a vehicle can cross a zone between two decisions).
"""

from __future__ import annotations

import math
from typing import Annotated, Any

import numpy as np
from pydantic import (
    Field,
    PrivateAttr,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from vo3d_opt.config import UNKNOWN_OPTION, check_options
from vo3d_opt.sim.dynamics import DynamicsConfig, WindConfig
from vo3d_opt.sim.scenario.geometry import nearby_pairs, prism_contains, sphere_surface_distance
from vo3d_opt.sim.scenario.specs import (
    OBSTACLE_TAGS,
    AgentSpec,
    BoxSpec,
    CylinderSpec,
    DefaultsSpec,
    ObstacleSpec,
    Problem,
    SafetySpec,
    SensingSpec,
    Spec,
    SphereSpec,
    Text,
)
from vo3d_opt.types import (
    Box,
    Cylinder,
    InputError,
    Limits,
    Neighbor,
    Positive,
    raise_problems,
)

#: The most control steps a run may take (``max_time / dt``): ten million steps of 0.2 s are
#: 23 days of flight; a run of one agent then holds about 1.5 GB of record.
MAX_STEPS = 10_000_000
#: The most RotorPy sub-steps per control period (``dynamics.substep_rate`` × ``dt``).
MAX_SUBSTEPS = 10_000

#: From this many vehicles a run under RotorPy one by one suggests ``batched: true``: at 50,
#: random-crossing-50 took 237 s batched against 1313 s one by one (at its default 100 Hz) in
#: docs/results/real-world.md.
BATCHED_ADVISED = 50


class Scenario(Spec):
    """A validated scenario. Build it with :func:`load_scenario` or :func:`scenario_from_dict`
    (which name the file in their errors), or ``Scenario.model_validate(data)``."""

    name: Text
    description: str = ""
    dt: Positive
    max_time: Positive
    goal_tolerance: Positive = 1.0
    limits: Limits
    sensing: SensingSpec = SensingSpec()
    defaults: DefaultsSpec = DefaultsSpec()
    agents: Annotated[list[AgentSpec], Field(min_length=1)]
    obstacles: list[ObstacleSpec] = []
    spheres: list[SphereSpec] = []
    velocity_response_tau: Positive | None = None
    dynamics: DynamicsConfig | None = None
    wind: WindConfig | None = None
    safety: SafetySpec = SafetySpec()
    formulation: Text | None = None
    solver: Text | None = None
    selector_options: dict[str, Any] = {}

    _source: str = PrivateAttr(default="<scenario>")
    _bodies: list[Cylinder | Box] = PrivateAttr(default_factory=list)

    def model_post_init(self, __context: Any) -> None:
        self._bodies = [spec.body() for spec in self.obstacles]

    # ---------------------------------------------------------------- selector keys, checked now

    @field_validator("formulation")
    @classmethod
    def _known_formulation(cls, name: str | None) -> str | None:
        from vo3d_opt.selector import FORMULATIONS  # late: loading a file needs no solver

        if name is not None and name not in FORMULATIONS:
            raise ValueError(f"unknown {name!r} (expected one of {', '.join(FORMULATIONS)})")
        return name

    @field_validator("solver")
    @classmethod
    def _known_solver(cls, name: str | None) -> str | None:
        from vo3d_opt.solvers import get_backend

        if name is not None:
            get_backend(name)  # ValueError listing the available ones
        return name

    @field_validator("selector_options")
    @classmethod
    def _known_options(cls, options: dict[str, Any]) -> dict[str, Any]:
        try:
            check_options(options)
        except InputError as exc:  # each problem at its own key, under this one
            errors: list[Any] = [
                {"type": "extra_forbidden", "loc": (k,), "input": options.get(k)}
                if m.startswith(UNKNOWN_OPTION)
                else {
                    "type": PydanticCustomError("value_error", "{problem}", {"problem": m}),
                    "loc": (k,),
                    "input": options.get(k),
                }
                for k, m in exc.problems
            ]
            raise ValidationError.from_exception_data("selector_options", errors) from None
        return options

    # ---------------------------------------------------------------------- cross-field checks

    @model_validator(mode="after")
    def _cross_field(self) -> Scenario:
        raise_problems("Scenario", self._cross_checks())
        return self

    def _cross_checks(self) -> list[Problem]:
        """Problems between keys, each at the key it concerns, in file order."""
        return (
            self._timing_problems()
            + self._real_world_problems()
            + self._step_problems()
            + self._agent_problems()
            + self._overlap_problems()
        )

    def _timing_problems(self) -> list[Problem]:
        out: list[Problem] = []
        if self.max_time > MAX_STEPS * self.dt:
            out.append(
                (
                    ("max_time",),
                    f"{self.max_time:g} s is more than {MAX_STEPS:,} steps of dt {self.dt:g} s",
                    self.max_time,
                )
            )
        if self.max_time < self.dt:
            out.append(
                (
                    ("max_time",),
                    f"{self.max_time:g} s is shorter than one step (dt {self.dt:g} s)",
                    self.max_time,
                )
            )
        v_lo = self.limits.v_min
        if self.defaults.max_speed < v_lo:
            out.append(
                (
                    ("defaults", "max_speed"),
                    f"{self.defaults.max_speed:g} is below the minimum speed {v_lo:g}",
                    self.defaults.max_speed,
                )
            )
        return out

    def _real_world_problems(self) -> list[Problem]:
        """The real-world keys that depend on others: one way to name the dynamics, wind
        only with RotorPy, a latency of whole steps."""
        out: list[Problem] = []
        if self.dynamics is not None and self.velocity_response_tau is not None:
            out.append(
                (
                    ("velocity_response_tau",),
                    "give either velocity_response_tau (an alias of dynamics model "
                    "first_order) or dynamics, not both",
                    self.velocity_response_tau,
                )
            )
        rate = self.dynamics.substep_rate if self.dynamics is not None else None
        if rate is not None and rate * self.dt > MAX_SUBSTEPS:
            out.append(
                (
                    ("dynamics", "substep_rate"),
                    f"{rate:g} Hz gives more than {MAX_SUBSTEPS:,} sub-steps per step of "
                    f"{self.dt:g} s",
                    rate,
                )
            )
        margin, room = self.safety.speed_margin, self.speed_room
        if margin is not None and margin >= room:
            out.append(
                (
                    ("safety", "speed_margin"),
                    f"must leave every vehicle some speed: below {room:g} (the smallest top "
                    "speed over limits.speed[0])",
                    margin,
                )
            )
        if self.wind is not None and self.vehicle_dynamics.model != "rotorpy":
            out.append(
                (
                    ("wind",),
                    f"only with dynamics model rotorpy, not {self.vehicle_dynamics.model}",
                    self.wind.type,
                )
            )
        steps = self.sensing.latency / self.dt
        if self.sensing.latency > self.max_time:
            out.append(
                (
                    ("sensing", "latency"),
                    f"{self.sensing.latency:g} s is longer than the run (max_time "
                    f"{self.max_time:g} s)",
                    self.sensing.latency,
                )
            )
        elif abs(steps - round(steps)) > 1e-6:
            out.append(
                (
                    ("sensing", "latency"),
                    f"must be a multiple of dt = {self.dt:g} s, got {self.sensing.latency:g}",
                    self.sensing.latency,
                )
            )
        return out

    def _step_problems(self) -> list[Problem]:
        step = float(np.max(self.max_speed)) * self.dt
        ranges = []
        if self.n_agents > 1:
            ranges.append(("vehicle_range", self.sensing.vehicle_range))
        if self.obstacles or self.spheres:
            ranges.append(("obstacle_range", self.sensing.obstacle_range))
        return [
            (
                ("dt",),
                f"one step flies {step:g} m (max_speed x dt), more than "
                f"sensing.{key} {value:g} m: what comes into range is passed before "
                f"the next decision; shorten dt",
                self.dt,
            )
            for key, value in ranges
            if step > value
        ]

    def _agent_problems(self) -> list[Problem]:
        out: list[Problem] = []
        seen: dict[str, int] = {}
        radius = self.radius
        v_lo, (z_lo, z_hi) = self.limits.v_min, self.limits.altitude
        for i, a in enumerate(self.agents):
            if a.id in seen:
                out.append(
                    (
                        ("agents", i, "id"),
                        f"duplicate id {a.id!r} (also agents[{seen[a.id]}])",
                        a.id,
                    )
                )
            seen.setdefault(a.id, i)
            if a.max_speed is not None and a.max_speed < v_lo:
                out.append(
                    (
                        ("agents", i, "max_speed"),
                        f"{a.max_speed:g} is below the minimum speed {v_lo:g}",
                        a.max_speed,
                    )
                )
            for key in ("start", "goal"):
                point = getattr(a, key)
                where = ("agents", i, key)
                if point[2] < z_lo:
                    out.append(
                        (where, f"below the altitude floor {z_lo:g} (z = {point[2]:g})", point)
                    )
                elif point[2] > z_hi:
                    out.append(
                        (where, f"above the altitude ceiling {z_hi:g} (z = {point[2]:g})", point)
                    )
                out += [(where, msg, point) for msg in self._inside_problems(point, radius[i])]
        return out

    def _inside_problems(self, point: np.ndarray, radius: float) -> list[str]:
        """A vehicle of this radius at ``point`` overlapping an obstacle or a physical sphere."""
        out = []
        for k, body in enumerate(self._bodies):
            d = float(body.surface_distance(point))
            if d < radius:
                out.append(
                    f"inside obstacles[{k}] ({self.obstacles[k].type} at {_fmt(body.center)}; "
                    f"{d:.3g} m from its surface, vehicle radius {radius:g} m)"
                )
        for k, s in enumerate(self.spheres):
            if s.physical and float(sphere_surface_distance(s.center, s.radius, point)) < radius:
                out.append(f"inside spheres[{k}] (at {_fmt(s.center)})")
        return out

    def _overlap_problems(self) -> list[Problem]:
        out: list[Problem] = []
        radius = self.radius
        for key, pts in (("start", self.starts), ("goal", self.goals)):
            for i, j, d in nearby_pairs(pts, radius, radius.max()):
                if d < radius[i] + radius[j]:
                    out.append(
                        (
                            ("agents", i, key),
                            f"overlaps agents[{j}] ({self.agents[j].id}) at {d:.3g} m",
                            pts[i],
                        )
                    )
        return out

    # -------------------------------------------------------------- convenience accessors

    @property
    def source(self) -> str:
        """The file the scenario was read from (``<scenario>`` when built in memory)."""
        return self._source

    @property
    def bodies(self) -> list[Cylinder | Box]:
        """Every obstacle as a ``types.Cylinder`` / ``types.Box``, in file order."""
        return list(self._bodies)

    @property
    def sensed(self) -> np.ndarray:
        """Boolean mask over ``bodies``: which obstacles the agents perceive."""
        return np.array([o.sensed for o in self.obstacles], dtype=bool)

    @property
    def n_agents(self) -> int:
        return len(self.agents)

    @property
    def ids(self) -> list[str]:
        return [a.id for a in self.agents]

    def _per_agent(self, key: str) -> np.ndarray:
        default = getattr(self.defaults, key)
        return np.array(
            [getattr(a, key) if getattr(a, key) is not None else default for a in self.agents],
            dtype=float,
        )

    @property
    def starts(self) -> np.ndarray:
        return np.array([a.start for a in self.agents], dtype=float).reshape(-1, 3)

    @property
    def goals(self) -> np.ndarray:
        return np.array([a.goal for a in self.agents], dtype=float).reshape(-1, 3)

    @property
    def r_pz(self) -> np.ndarray:
        """Protected-zone radius per agent, m."""
        return self._per_agent("r_pz")

    @property
    def radius(self) -> np.ndarray:
        """Physical radius per agent, m."""
        return self._per_agent("radius")

    @property
    def max_speed(self) -> np.ndarray:
        """Speed bound per agent: min(limits.speed[1], the agent's max_speed), m/s."""
        return np.minimum(self._per_agent("max_speed"), self.limits.v_max)

    @property
    def cruise_speed(self) -> np.ndarray:
        """The speed each agent prefers on its way, m/s: its ``cruise_speed`` (or the
        defaults'), else its speed bound; never above the bound."""
        default = self.defaults.cruise_speed
        wanted = [a.cruise_speed if a.cruise_speed is not None else default for a in self.agents]
        cruise = np.array([np.inf if w is None else w for w in wanted], dtype=float)
        return np.minimum(cruise, self.max_speed)

    @property
    def sensing_horizon(self) -> float:
        """``sensing.vehicle_range / (2 v_max)`` (s), v_max the top agent speed: the time two
        vehicles closing head-on at full speed take to cross the sensing range, RVO2-3D's time
        horizon in ``baselines.rvo2``, and what ``selector_options: {horizon: sensing}``
        stands for while the derived acceleration bound lets a vehicle take any velocity
        within a step (none otherwise: ``config.turns_at_once``)."""
        return float(self.sensing.vehicle_range / (2.0 * float(np.max(self.max_speed))))

    @property
    def speed_room(self) -> float:
        """The smallest top speed over the minimum speed among the vehicles that avoid (all of
        them if none does), m/s: the most a speed margin may take."""
        tops = self.max_speed[self.avoids] if self.avoids.any() else self.max_speed
        return float(np.min(tops)) - self.limits.v_min

    @property
    def avoids(self) -> np.ndarray:
        """(N,) bool: which agents avoid (``avoids: false`` ones fly straight to their goal)."""
        return np.array([a.avoids for a in self.agents], dtype=bool)

    @property
    def vehicle_dynamics(self) -> DynamicsConfig:
        """The ``dynamics`` mapping in effect: the given one, ``first_order`` with
        ``velocity_response_tau`` (its alias), or the default ``kinematic``."""
        if self.dynamics is not None:
            return self.dynamics
        if self.velocity_response_tau is not None:
            return DynamicsConfig(model="first_order", tau=self.velocity_response_tau)
        return DynamicsConfig()

    @property
    def n_steps(self) -> int:
        """Most control periods the run may take (max_time / dt, rounded up)."""
        return max(1, int(math.ceil(self.max_time / self.dt - 1e-9)))

    def agent_limits(self, i: int) -> Limits:
        """The ``types.Limits`` handed to agent ``i``'s selector."""
        return self.limits.model_copy(
            update={"speed": (self.limits.v_min, float(self.max_speed[i]))}
        )

    def sphere_neighbors(self) -> list[Neighbor]:
        """The ``spheres`` as zero-velocity neighbours (r_pz = radius + margin)."""
        return [
            Neighbor(position=s.center, velocity=(0.0, 0.0, 0.0), r_pz=s.r_pz, cooperative=False)
            for s in self.spheres
        ]

    def warnings(self) -> list[str]:
        """What is allowed but worth saying before a run, one line each: starts inside a
        protected zone, steps longer than a protected-zone radius, a swarm under RotorPy one
        vehicle at a time."""
        return self.start_warnings() + self.step_warnings() + self.dynamics_warnings()

    def dynamics_warnings(self) -> list[str]:
        """A swarm under RotorPy integrated one vehicle at a time, where ``batched: true`` is
        several times cheaper (``BATCHED_ADVISED``, formulations/dynamics.md)."""
        dyn = self.vehicle_dynamics
        if dyn.model != "rotorpy" or dyn.batched or self.n_agents < BATCHED_ADVISED:
            return []
        return [
            f"{self.n_agents} vehicles under RotorPy one at a time (tens of ms each per "
            "period): dynamics.batched: true flies them in one batch, many times cheaper "
            "(needs the batched extra)"
        ]

    def step_warnings(self) -> list[str]:
        """Agents that fly farther than their protected-zone radius in one step."""
        step, r_pz = self.max_speed * self.dt, self.r_pz
        return [
            f"{a.id} flies {step[i]:g} m per step (max_speed x dt), more than its protected-zone "
            f"radius {r_pz[i]:g} m: it can cross a zone between two decisions"
            for i, a in enumerate(self.agents)
            if step[i] > r_pz[i]
        ]

    def start_warnings(self) -> list[str]:
        """Starts inside a protected zone (allowed, but worth saying): one line each."""
        out: list[str] = []
        p, r_pz, ids = self.starts, self.r_pz, self.ids
        pairs = sorted((j, i, d) for i, j, d in nearby_pairs(p, r_pz, 0.5 * r_pz.max()))
        for i, j, d in pairs:
            if d < max(r_pz[i], r_pz[j]):
                out.append(
                    f"{ids[i]} and {ids[j]} start {d:.2f} m apart, inside the "
                    f"protected zone ({max(r_pz[i], r_pz[j]):g} m)"
                )
        for k, body in enumerate(self._bodies):
            out += [
                f"{ids[a]} starts inside the protected prism of obstacles[{k}]"
                for a in np.flatnonzero(prism_contains(body, p))
            ]
        for k, s in enumerate(self.spheres):
            d = np.linalg.norm(p - np.asarray(s.center), axis=1)
            out += [
                f"{ids[a]} starts inside the protected zone of spheres[{k}]"
                for a in np.flatnonzero(d < s.r_pz)
            ]
        return out


def _fmt(v: Any) -> str:
    return "(" + ", ".join(f"{float(x):g}" for x in v) + ")"


__all__ = [
    "OBSTACLE_TAGS",
    "AgentSpec",
    "BoxSpec",
    "CylinderSpec",
    "DefaultsSpec",
    "ObstacleSpec",
    "Scenario",
    "SafetySpec",
    "SensingSpec",
    "SphereSpec",
    "Spec",
    "prism_contains",
    "sphere_surface_distance",
]
