"""Scenario files (contract §2): pydantic models of the YAML format and a strict loader.

A scenario file is a YAML mapping::

    name: paper-case1-ten-uav-crossing     # required, unique among the bundled files
    description: free text                 # optional
    dt: 0.2                                # required: control and integration period, s
    max_time: 150.0                        # required: s; the run stops earlier when all arrived
    goal_tolerance: 1.0                    # m (default 1.0)
    limits:                                # required
      speed: [0.0, 4.0]                    # m/s: [v_min, v_max], v_min <= v_max, v_max > 0
      altitude: [0.0, 40.0]                # m: [z_min, z_max], z_min < z_max
      acceleration: 3.0                    # optional, m/s², handed to the selector's Limits
    sensing:                               # default: Table 1 of the paper (55 m both)
      vehicle_range: 55.0                  # m, centre to centre
      obstacle_range: 55.0                 # m, to the nearest point of the obstacle
    defaults:                              # default: r_pz 10, radius 0.5, max_speed 4
      r_pz: 10.0                           # protected-zone radius, m
      radius: 0.5                          # physical radius, m (collision counting)
      max_speed: 4.0                       # m/s
    agents:                                # required, at least one
      - {id: u0, start: [40, 0, 20], goal: [-40, 0, 20]}
      - {id: u1, start: [-40, 0, 20], goal: [40, 0, 20], r_pz: 8.0, radius: 0.3, max_speed: 3}
    obstacles:                             # optional; they stand on the ground (z = 0)
      - {type: cylinder, center: [0, 10], radius: 3, height: 30}
      - {type: box, center: [10, -10], size: [6, 6], height: 25, yaw: 0.3}

Extensions beyond the contract (all optional):

* obstacle keys ``L_pz``, ``h_pz`` (side and height of the tall square protected prism C_pz of
  the paper's section 4; derived from the size plus ``margin`` when omitted, see
  ``vo3d_opt.types``), ``margin`` (m, default ``types.PZ_MARGIN``) and ``sensed`` (default
  ``true``). An obstacle with ``sensed: false`` is physical (it counts in the metrics and is
  drawn) but no agent perceives it; used to fly the original method's sphere approximation
  around the real cylinders (paper case 3, Fig. 18).
* ``spheres``: a list of ``{center: [x, y, z], radius: r, margin: m, physical: true}``. Each
  sphere is given to the selector as a static ``Neighbor`` (velocity 0, r_pz = radius + margin),
  which is how the original 3D VO of Jenie et al. handles static obstacles. ``physical: false``
  spheres are seen by the agents but ignored by the metrics (they only approximate another
  obstacle). ``margin`` defaults to ``types.PZ_MARGIN``.
* ``velocity_response_tau`` (s): first-order velocity response ``v += (v_cmd - v) * dt / tau``
  (clamped to a full step when ``dt >= tau``); off (ideal kinematics) when omitted.
* ``formulation``, ``solver``: defaults for ``vo3d run`` when the command line gives none.
* ``selector_options``: a mapping passed as extra keyword arguments to ``VelocitySelector``.

Rejected, with a one-line ``ScenarioError`` naming the file and the key path: unreadable files,
invalid YAML, duplicate YAML keys, unknown or missing keys, wrong types (no strings for numbers,
no booleans for numbers), NaN or infinite numbers, non-positive dt / max_time / goal_tolerance /
radii / sizes / heights / ranges / speeds, empty speed or altitude ranges, starts or goals
outside the altitude range, a start or goal inside (overlapping) an obstacle or a physical
sphere, two vehicles overlapping at the start or at the goal, duplicate agent ids, a protected
prism smaller than its obstacle, an agent max_speed below the minimum speed. Starting inside a
protected zone or prism is allowed: ``Scenario.start_warnings()`` and the run's summary
(``starts_inside_pz``) report it.
"""
from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    PrivateAttr,
    ValidationError,
)

from vo3d_opt.types import PZ_MARGIN, Box, Cylinder, Finite, Limits, Neighbor, NonNegative, Positive


class ScenarioError(ValueError):
    """An unreadable or invalid scenario file; the message is one line: ``file: key: problem``."""


# ---------------------------------------------------------------------------------- fields


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _vector(n: int):
    def check(value: Any) -> tuple[float, ...]:
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise ValueError(f"must be a list of {n} numbers, got {_short(value)}")
        if not all(_is_number(x) for x in value):
            raise ValueError(f"must be a list of {n} numbers, got {_short(value)}")
        if not all(math.isfinite(float(x)) for x in value):
            raise ValueError("must be finite (no NaN or inf)")
        return tuple(float(x) for x in value)

    return check


Vec2 = Annotated[tuple[float, float], PlainValidator(_vector(2))]
Vec3 = Annotated[tuple[float, float, float], PlainValidator(_vector(3))]
Range = Annotated[tuple[float, float], PlainValidator(_vector(2))]
Text = Annotated[str, Field(min_length=1)]


def _short(value: Any, limit: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class LimitsSpec(_Spec):
    """Speed (m/s) and altitude (m) ranges of Table 1, plus an optional acceleration bound."""

    speed: Range
    altitude: Range
    acceleration: Positive | None = None


class SensingSpec(_Spec):
    """Sensing ranges of Table 1: vehicles by centre distance, obstacles by nearest point."""

    vehicle_range: Positive = 55.0
    obstacle_range: Positive = 55.0


class DefaultsSpec(_Spec):
    """Per-agent parameters unless an agent overrides them (section 5: r_pz = 10 m)."""

    r_pz: Positive = 10.0
    radius: Positive = 0.5
    max_speed: Positive = 4.0


class AgentSpec(_Spec):
    """One UAV: identifier, start and goal positions (m) and optional parameter overrides."""

    id: Text
    start: Vec3
    goal: Vec3
    r_pz: Positive | None = None
    radius: Positive | None = None
    max_speed: Positive | None = None


class _ObstacleSpec(_Spec):
    center: Vec2
    height: Positive
    L_pz: Positive | None = None
    h_pz: Positive | None = None
    margin: NonNegative | None = None
    sensed: bool = True

    def _common(self) -> dict[str, Any]:
        out: dict[str, Any] = {"center": self.center, "height": self.height}
        for key in ("L_pz", "h_pz", "margin"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out


class CylinderSpec(_ObstacleSpec):
    """A vertical cylinder standing on the ground (section 4.1)."""

    type: Literal["cylinder"]
    radius: Positive

    def body(self) -> Cylinder:
        return Cylinder(radius=self.radius, **self._common())


class BoxSpec(_ObstacleSpec):
    """A (possibly yawed) box standing on the ground (section 4.3)."""

    type: Literal["box"]
    size: Vec2
    yaw: Finite = 0.0

    def body(self) -> Box:
        return Box(size=self.size, yaw=self.yaw, **self._common())


class SphereSpec(_Spec):
    """A static sphere, seen by the agents as a zero-velocity Neighbor (original 3D VO)."""

    center: Vec3
    radius: Positive
    margin: NonNegative = PZ_MARGIN
    physical: bool = True

    @property
    def r_pz(self) -> float:
        return self.radius + self.margin


ObstacleSpec = Annotated[Union[CylinderSpec, BoxSpec], Field(discriminator="type")]


class Scenario(_Spec):
    """A validated scenario. Build it with :func:`load_scenario` or :func:`scenario_from_dict`
    (constructing it directly skips the cross-field checks)."""

    name: Text
    description: str = ""
    dt: Positive
    max_time: Positive
    goal_tolerance: Positive = 1.0
    limits: LimitsSpec
    sensing: SensingSpec = SensingSpec()
    defaults: DefaultsSpec = DefaultsSpec()
    agents: Annotated[list[AgentSpec], Field(min_length=1)]
    obstacles: list[ObstacleSpec] = []
    spheres: list[SphereSpec] = []
    velocity_response_tau: Positive | None = None
    formulation: Text | None = None
    solver: Text | None = None
    selector_options: dict[str, Any] = {}

    _source: str = PrivateAttr(default="<scenario>")
    _bodies: list[Cylinder | Box] = PrivateAttr(default_factory=list)

    def model_post_init(self, __context: Any) -> None:
        bodies = []
        for spec in self.obstacles:
            try:
                bodies.append(spec.body())
            except ValueError:  # reported with its key path by _semantic_errors
                bodies.append(None)
        self._bodies = bodies

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
            [getattr(a, key) if getattr(a, key) is not None else default for a in self.agents]
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
        return self._per_agent("r_pz").astype(float)

    @property
    def radius(self) -> np.ndarray:
        """Physical radius per agent, m."""
        return self._per_agent("radius").astype(float)

    @property
    def max_speed(self) -> np.ndarray:
        """Speed bound per agent: min(limits.speed[1], the agent's max_speed), m/s."""
        return np.minimum(self._per_agent("max_speed").astype(float), self.limits.speed[1])

    @property
    def n_steps(self) -> int:
        """Most control periods the run may take (max_time / dt, rounded up)."""
        return max(1, int(math.ceil(self.max_time / self.dt - 1e-9)))

    def agent_limits(self, i: int) -> Limits:
        """The ``types.Limits`` handed to agent ``i``'s selector."""
        return Limits(
            speed=(self.limits.speed[0], float(self.max_speed[i])),
            altitude=self.limits.altitude,
            acceleration=self.limits.acceleration,
        )

    def sphere_neighbors(self) -> list[Neighbor]:
        """The ``spheres`` as zero-velocity neighbours (r_pz = radius + margin)."""
        return [Neighbor(position=s.center, velocity=(0.0, 0.0, 0.0), r_pz=s.r_pz, cooperative=False)
                for s in self.spheres]

    def start_warnings(self) -> list[str]:
        """Starts inside a protected zone (allowed, but worth saying): one line each."""
        out: list[str] = []
        p, r_pz, ids = self.starts, self.r_pz, self.ids
        n = len(ids)
        for i in range(n):
            for j in range(i + 1, n):
                d = float(np.linalg.norm(p[i] - p[j]))
                if d < max(r_pz[i], r_pz[j]):
                    out.append(f"{ids[i]} and {ids[j]} start {d:.2f} m apart, inside the "
                               f"protected zone ({max(r_pz[i], r_pz[j]):g} m)")
        for k, body in enumerate(self._bodies):
            inside = prism_contains(body, p)
            for i in np.flatnonzero(inside):
                out.append(f"{ids[i]} starts inside the protected prism of obstacles[{k}]")
        for k, s in enumerate(self.spheres):
            d = np.linalg.norm(p - np.asarray(s.center), axis=1)
            for i in np.flatnonzero(d < s.r_pz):
                out.append(f"{ids[i]} starts inside the protected zone of spheres[{k}]")
        return out


# ------------------------------------------------------------------------------ geometry


def prism_contains(body: Cylinder | Box, points: np.ndarray) -> np.ndarray:
    """Whether points (..., 3) lie inside the obstacle's protected prism C_pz.

    Section 4.1: the square prism turns so that a side faces the vehicle, so in the horizontal
    plane the vehicle is inside exactly when its distance to the obstacle's axis is below
    L_pz / 2; vertically the prism spans [0, h_pz].
    """
    p = np.asarray(points, dtype=float)
    horizontal = np.linalg.norm(p[..., :2] - np.asarray(body.center), axis=-1)
    return (horizontal < body.side / 2.0) & (p[..., 2] < body.prism_height) & (p[..., 2] >= 0.0)


def sphere_surface_distance(center: np.ndarray, radius: float, points: np.ndarray) -> np.ndarray:
    """Distance (m) from points (..., 3) to a sphere's surface (0 inside)."""
    p = np.asarray(points, dtype=float)
    return np.maximum(np.linalg.norm(p - np.asarray(center, dtype=float), axis=-1) - radius, 0.0)


# -------------------------------------------------------------------------------- loading


class _UniqueKeyLoader(yaml.SafeLoader):
    """A SafeLoader that rejects duplicate mapping keys (PyYAML keeps the last silently)."""


def _construct_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False):
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        try:
            hashable = key in seen
        except TypeError:
            hashable = False
        if hashable:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark)
        try:
            seen.add(key)
        except TypeError:
            pass
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _all_keys() -> set[str]:
    keys: set[str] = set()
    for model in (Scenario, LimitsSpec, SensingSpec, DefaultsSpec, AgentSpec, CylinderSpec,
                  BoxSpec, SphereSpec):
        keys.update(model.model_fields)
    return keys


_TAGS = {"cylinder", "box"}


def _key_path(loc: tuple[Any, ...]) -> str:
    out = ""
    prev: Any = None
    for i, part in enumerate(loc):
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in _TAGS and isinstance(prev, int) and i >= 2 and loc[i - 2] == "obstacles":
            pass  # pydantic's discriminator tag, not a key of the file
        else:
            out += ("." if out else "") + str(part)
        prev = part
    return out


def _describe(err: dict[str, Any]) -> tuple[str, str]:
    loc = tuple(err.get("loc", ()))
    kind = err.get("type", "")
    path = _key_path(loc)
    if kind == "missing":
        return path, "missing required key"
    if kind == "extra_forbidden":
        key = str(loc[-1]) if loc else "?"
        hint = difflib.get_close_matches(key, sorted(_all_keys()), n=1)
        return path, "unknown key" + (f" (did you mean {hint[0]!r}?)" if hint else "")
    if kind == "union_tag_invalid":
        tag = err.get("ctx", {}).get("tag", "?")
        return f"{path}.type", f"unknown obstacle type {tag!r} (expected 'cylinder' or 'box')"
    if kind == "union_tag_not_found":
        return f"{path}.type", "missing required key"
    msg = str(err.get("msg", "invalid"))
    msg = msg.removeprefix("Value error, ")
    msg = msg[:1].lower() + msg[1:]
    if kind.endswith("_type") or kind.endswith("_parsing"):
        msg += f", got {_short(err.get('input'))}"
    return path, msg


def _semantic_errors(sc: Scenario) -> list[tuple[str, str]]:
    """Cross-field checks (key path, problem), in file order."""
    errs: list[tuple[str, str]] = []
    v_lo, v_hi = sc.limits.speed
    z_lo, z_hi = sc.limits.altitude
    if v_lo < 0:
        errs.append(("limits.speed", f"minimum speed {v_lo:g} is negative"))
    if v_hi <= 0:
        errs.append(("limits.speed", f"maximum speed {v_hi:g} must be positive"))
    if v_lo > v_hi:
        errs.append(("limits.speed", f"empty range [{v_lo:g}, {v_hi:g}]"))
    if z_lo >= z_hi:
        errs.append(("limits.altitude", f"empty range [{z_lo:g}, {z_hi:g}]"))
    if sc.max_time < sc.dt:
        errs.append(("max_time", f"{sc.max_time:g} s is shorter than one step (dt {sc.dt:g} s)"))
    if sc.defaults.max_speed < v_lo:
        errs.append(("defaults.max_speed", f"{sc.defaults.max_speed:g} is below the minimum "
                                           f"speed {v_lo:g}"))

    for k, spec in enumerate(sc.obstacles):
        where = f"obstacles[{k}]"
        if isinstance(spec, BoxSpec) and min(spec.size) <= 0:
            errs.append((f"{where}.size", "both sides must be positive"))
            continue
        if spec.h_pz is not None and spec.h_pz < spec.height:
            errs.append((f"{where}.h_pz", f"{spec.h_pz:g} is below the obstacle height "
                                          f"{spec.height:g} (section 4.1: h_pz > height)"))
        extent = 2 * spec.radius if isinstance(spec, CylinderSpec) else math.hypot(*spec.size)
        if spec.L_pz is not None and spec.L_pz < extent:
            errs.append((f"{where}.L_pz", f"{spec.L_pz:g} is below the obstacle's largest "
                                          f"extent {extent:.3g} (section 4.1)"))
        if sc._bodies[k] is None and not any(e[0].startswith(where) for e in errs):
            try:
                spec.body()
            except ValueError as exc:
                errs.append((where, str(exc).splitlines()[-1].strip()))

    seen: dict[str, int] = {}
    radius = sc.radius
    for i, a in enumerate(sc.agents):
        where = f"agents[{i}]"
        if a.id in seen:
            errs.append((f"{where}.id", f"duplicate id {a.id!r} (also agents[{seen[a.id]}])"))
        seen.setdefault(a.id, i)
        if a.max_speed is not None and a.max_speed < v_lo:
            errs.append((f"{where}.max_speed", f"{a.max_speed:g} is below the minimum speed "
                                               f"{v_lo:g}"))
        for key in ("start", "goal"):
            z = getattr(a, key)[2]
            if z < z_lo:
                errs.append((f"{where}.{key}", f"below the altitude floor {z_lo:g} (z = {z:g})"))
            elif z > z_hi:
                errs.append((f"{where}.{key}", f"above the altitude ceiling {z_hi:g} (z = {z:g})"))
            point = np.asarray(getattr(a, key))
            for k, body in enumerate(sc._bodies):
                if body is None:
                    continue
                d = float(body.surface_distance(point))
                if d < radius[i]:
                    errs.append((f"{where}.{key}", f"inside obstacles[{k}] ({sc.obstacles[k].type}"
                                                   f" at {_fmt(body.center)}; {d:.3g} m from its "
                                                   f"surface, vehicle radius {radius[i]:g} m)"))
            for k, s in enumerate(sc.spheres):
                d = float(sphere_surface_distance(np.asarray(s.center), s.radius, point))
                if s.physical and d < radius[i]:
                    errs.append((f"{where}.{key}", f"inside spheres[{k}] (at {_fmt(s.center)})"))
    starts, goals = sc.starts, sc.goals
    for key, pts in (("start", starts), ("goal", goals)):
        for i in range(len(pts)):
            for j in range(i):
                d = float(np.linalg.norm(pts[i] - pts[j]))
                if d < radius[i] + radius[j]:
                    errs.append((f"agents[{i}].{key}", f"overlaps agents[{j}] ({sc.agents[j].id})"
                                                       f" at {d:.3g} m"))
    errs += _selector_errors(sc)
    order = {k: n for n, k in enumerate(Scenario.model_fields)}
    return sorted(errs, key=lambda e: order.get(e[0].split(".")[0].split("[")[0], 99))


def _selector_errors(sc: Scenario) -> list[tuple[str, str]]:
    """The scenario's selector defaults, checked now rather than when the run starts."""
    from vo3d_opt.selector import FORMULATIONS, Options
    from vo3d_opt.solvers import get_backend

    errs = []
    try:
        Options(**sc.selector_options)
    except ValidationError as exc:
        for err in exc.errors():
            path, msg = _describe(err)
            errs.append((f"selector_options.{path}", msg))
    if sc.formulation is not None and sc.formulation not in FORMULATIONS:
        errs.append(("formulation", f"unknown {sc.formulation!r} (expected one of {', '.join(FORMULATIONS)})"))
    if sc.solver is not None:
        try:
            get_backend(sc.solver)
        except ValueError as exc:
            errs.append(("solver", str(exc)))
    return errs


def _fmt(v: Any) -> str:
    return "(" + ", ".join(f"{float(x):g}" for x in v) + ")"


def _fail(source: str, problems: list[tuple[str, str]]) -> ScenarioError:
    path, msg = problems[0]
    more = f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''})" \
        if len(problems) > 1 else ""
    text = f"{source}: {path}: {msg}{more}" if path else f"{source}: {msg}{more}"
    return ScenarioError(" ".join(text.split()))


def scenario_from_dict(data: Any, source: str = "<scenario>") -> Scenario:
    """Validate already-parsed YAML data; ``source`` names it in error messages."""
    if not isinstance(data, dict):
        raise _fail(source, [("", f"must be a YAML mapping of keys, got {type(data).__name__}")])
    try:
        sc = Scenario.model_validate(data)
    except ValidationError as exc:
        raise _fail(source, [_describe(e) for e in exc.errors()]) from None
    problems = _semantic_errors(sc)
    if problems:
        raise _fail(source, problems)
    sc._source = source
    return sc


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file; raise :class:`ScenarioError` (one line) if invalid."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ScenarioError(f"{source}: cannot read: {reason}") from None
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise ScenarioError(" ".join(f"{source}: {where}invalid YAML: {problem}".split())) \
            from None
    return scenario_from_dict(data, source)


# ------------------------------------------------------------------------ bundled files


def bundled_dir() -> Path:
    """The repository's ``scenarios/`` directory (next to the ``vo3d_opt`` package)."""
    return Path(__file__).resolve().parents[2] / "scenarios"


def bundled_files() -> list[Path]:
    """Every bundled scenario file, sorted by file name."""
    d = bundled_dir()
    return sorted(d.glob("*.yaml")) if d.is_dir() else []


def resolve(arg: str | Path) -> Path:
    """A scenario argument: an existing path, else a bundled scenario's name or file stem."""
    p = Path(arg)
    if p.exists() or p.suffix in (".yaml", ".yml") or len(p.parts) > 1:
        return p
    for f in bundled_files():
        if f.stem == str(arg):
            return f
    for f in bundled_files():
        try:
            if load_scenario(f).name == str(arg):
                return f
        except ScenarioError:
            continue
    return p
