"""Random encounters for sweeps: what a family is, and how encounter ``index`` of a sweep is
drawn, checked and named (the families themselves: :mod:`.families`).

Each family draws one encounter from stated parameter distributions (written out per family
below and in ``scenarios/README.md``, "Sweep families"). Encounter ``index`` of a sweep with
``seed`` uses its own stream, ``numpy.random.default_rng(SeedSequence([seed, index]))``, so any
single encounter is regenerated alone by :func:`make_encounter` and the first N encounters do
not depend on N.

A draw is kept only when it is a *valid encounter* (:func:`encounter_problems`): the loader
accepts it, nobody starts inside a protected zone or prism, and the starts and goals of
different agents are at least ``SEPARATION`` times the larger protected-zone radius apart (so
that no intrusion is forced at a start or at a hovering goal), and no start or goal lies within
``PRISM_CLEARANCE`` of an obstacle's protected prism. Otherwise the next draw from the *same*
stream is tried, so the rejection is deterministic. ``max_time`` leaves every agent twice its
straight-line flight time plus 30 s.

A family is a function ``rng -> Draw`` registered with :func:`register`; a family built on
another one (e.g. a ``group`` plus scenario keys) calls that one's function and edits the dict.
The helpers of the draws (rounding, placing points apart, the scenario's base keys) are here
beside them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, get_args

import numpy as np
from pydantic import BaseModel

from vo3d_opt.sim.scenario import Scenario, ScenarioError, scenario_from_dict

#: Starts and goals of two different agents are at least this many times max(r_pz) apart.
SEPARATION = 1.25
#: Starts and goals keep this much horizontal clearance (m) from every protected prism.
PRISM_CLEARANCE = 2.0
#: max_time = TIME_FACTOR * (longest straight flight time) + TIME_SLACK.
TIME_FACTOR, TIME_SLACK = 2.0, 30.0
DT = 0.2
#: Decimals (mm) to which positions and sizes are to_mm: readable, exactly replayable YAML.
DECIMALS = 3
#: Speeds keep more (a mm/s error would move a vehicle by cm over a flight).
SPEED_DECIMALS = 6


@dataclass(frozen=True)
class Draw:
    """One draw of a family: its parameters (scalars, the parquet columns ``param_*``) and the
    scenario dict (a scenario file's keys but ``name`` and ``description``, which the sweep
    sets)."""

    params: dict[str, float | int | str]
    scenario: dict[str, Any]


#: A family's draw function; None means "this draw failed, draw again" (from the same stream).
Generator = Callable[[np.random.Generator], "Draw | None"]


@dataclass(frozen=True)
class Family:
    """A named encounter generator. ``obstacle_free``: no encounter has obstacles, so RVO2-3D
    can fly it (``--method rvo2``). ``warm_keys``: scenario keys added to the workers' warm-up
    encounter, so that it runs the same code as the family's (e.g. its ``dynamics``).
    ``needs``: the scenario keys (dotted paths) its draws use that not every build's schema
    defines (the real-world keys); the sweep refuses the family while one is missing.
    ``extras``: the optional extras its encounters need (the sweep refuses the family without
    them). ``batched``: its encounters can fly side by side (``vo3d_opt.sim.lockstep`` for
    kinematic or first-order dynamics, one ``vo3d_opt.sim.rotorpy_fleet.RotorPyFleet`` for
    batched RotorPy vehicles), so a sweep hands a task many of them; else one each (an
    encounter of seconds or minutes is a task of its own)."""

    name: str
    summary: str
    generate: Generator
    obstacle_free: bool
    max_attempts: int = 1000
    warm_keys: dict[str, Any] = field(default_factory=dict)
    needs: tuple[str, ...] = ()
    batched: bool = True
    extras: tuple[str, ...] = ()

    def missing_keys(self) -> list[str]:
        """The scenario keys of ``needs`` (dotted paths, e.g. ``sensing.latency``) that this
        build's scenario schema does not define: the family cannot run while any is missing."""
        return [path for path in self.needs if not schema_has(path)]


@dataclass(frozen=True)
class SweepEncounter:
    """Encounter ``index`` of ``family`` with ``seed``: its parameters, the scenario dict (with
    name and description) and the draws it took (rejected ones included)."""

    family: str
    seed: int
    index: int
    attempts: int
    params: dict[str, float | int | str]
    scenario: dict[str, Any] = field(repr=False)
    #: The scenario as the validity check loaded it (``load`` returns it: loading is pure).
    loaded: Scenario | None = field(default=None, repr=False, compare=False)

    def load(self) -> Scenario:
        if self.loaded is not None:
            return self.loaded
        return scenario_from_dict(self.scenario, source=self.scenario["name"])


def _submodel(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model inside a field's annotation (``M``, ``list[M]``, ``M | None``...)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in get_args(annotation):
        found = _submodel(arg)
        if found is not None:
            return found
    return None


def schema_has(path: str) -> bool:
    """Whether the scenario schema defines the dotted key ``path`` (``agents.avoids`` is a key
    of every agent)."""
    model: type[BaseModel] | None = Scenario
    for part in path.split("."):
        if model is None or part not in model.model_fields:
            return False
        model = _submodel(model.model_fields[part].annotation)
    return True


FAMILIES: dict[str, Family] = {}


def register(
    name: str,
    summary: str,
    *,
    obstacle_free: bool,
    warm_keys: dict[str, Any] | None = None,
    needs: tuple[str, ...] = (),
    batched: bool = True,
    extras: tuple[str, ...] = (),
) -> Callable[[Generator], Generator]:
    """Decorator: register ``rng -> Draw`` as family ``name`` (``summary``: one line for
    ``vo3d sweep --list``; the rest as in :class:`Family`)."""

    def wrap(fn: Generator) -> Generator:
        FAMILIES[name] = Family(
            name=name,
            summary=summary,
            generate=fn,
            obstacle_free=obstacle_free,
            warm_keys=dict(warm_keys or {}),
            needs=tuple(needs),
            batched=batched,
            extras=tuple(extras),
        )
        return fn

    return wrap


def get_family(name: str | Family) -> Family:
    """The registered family ``name`` (a :class:`Family` is returned as is); ``ValueError``
    naming the known ones otherwise."""
    if isinstance(name, Family):
        return name
    try:
        return FAMILIES[name]
    except KeyError:
        raise ValueError(
            f"family: unknown {name!r} (expected one of {', '.join(FAMILIES)})"
        ) from None


def encounter_rng(seed: int, index: int) -> np.random.Generator:
    """The random stream of encounter ``index`` of a sweep with ``seed`` (both >= 0)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(index)]))


def encounter_name(family: str, seed: int, index: int) -> str:
    return f"{family}-s{seed}-i{index}"


def make_encounter(family: str | Family, seed: int, index: int) -> SweepEncounter:
    """Draw encounter ``index`` of ``family`` with ``seed``, retrying until it is valid.

    ``RuntimeError`` if ``max_attempts`` draws were all invalid (a family that cannot be met).
    """
    fam = get_family(family)
    if int(seed) < 0 or int(index) < 0:
        raise ValueError(f"seed and index must be >= 0, got seed={seed}, index={index}")
    rng = encounter_rng(seed, index)
    name = encounter_name(fam.name, seed, index)
    last: list[str] = []
    for attempt in range(1, fam.max_attempts + 1):
        draw = fam.generate(rng)
        if draw is None:
            last = ["the generator rejected its own draw"]
            continue
        data = {
            "name": name,
            "description": f"Encounter {index} of the '{fam.name}' sweep family with seed "
            f"{seed} (regenerate: vo3d_opt.sweep.make_encounter("
            f"'{fam.name}', {seed}, {index})).",
            **draw.scenario,
        }
        sc, last = _checked(data, name)
        if not last:
            return SweepEncounter(
                family=fam.name,
                seed=int(seed),
                index=int(index),
                attempts=attempt,
                params=dict(draw.params),
                scenario=data,
                loaded=sc,
            )
    raise RuntimeError(
        f"{name}: no valid encounter in {fam.max_attempts} draws (last problem: {last[0]})"
    )


def encounter_problems(data: dict[str, Any], source: str = "<encounter>") -> list[str]:
    """Why ``data`` is not a valid sweep encounter (empty list: it is); see the module doc."""
    return _checked(data, source)[1]


def _checked(data: dict[str, Any], source: str) -> tuple[Scenario | None, list[str]]:
    """The scenario ``data`` loads to (None when the loader refuses it) and why it is not a
    valid sweep encounter (empty: it is)."""
    try:
        sc = scenario_from_dict(data, source=source)
    except ScenarioError as exc:
        return None, [str(exc)]
    problems = sc.start_warnings()
    points = np.concatenate([sc.starts, sc.goals])
    owner = np.tile(np.arange(sc.n_agents), 2)
    r_pz = np.tile(sc.r_pz, 2)
    d = np.linalg.norm(points[:, None] - points[None, :], axis=-1)
    need = SEPARATION * np.maximum(r_pz[:, None], r_pz[None, :])
    close = (d < need) & (owner[:, None] != owner[None, :])
    if close.any():
        a, b = np.argwhere(close)[0]
        problems.append(f"points of agents {owner[a]} and {owner[b]} are {d[a, b]:.2f} m apart")
    for k, body in enumerate(sc.bodies):
        horizontal = np.linalg.norm(points[:, :2] - np.asarray(body.center), axis=1)
        near = (horizontal < body.side / 2 + PRISM_CLEARANCE) & (
            points[:, 2] < body.prism_height + PRISM_CLEARANCE
        )
        if near.any():
            problems.append(
                f"a start or goal is within {PRISM_CLEARANCE:g} m of the protected "
                f"prism of obstacles[{k}]"
            )
    return sc, problems


# ----------------------------------------------------------------------------- helpers


def to_mm(x: Any, decimals: int = DECIMALS) -> Any:
    """Round numbers (and lists of them) to ``decimals``, as plain Python floats."""
    if isinstance(x, (list, tuple, np.ndarray)):
        return [to_mm(v, decimals) for v in x]
    return round(float(x), decimals)


def max_time_for(starts: np.ndarray, goals: np.ndarray, speeds: np.ndarray) -> float:
    flight = np.linalg.norm(goals - starts, axis=1) / speeds
    return float(math.ceil(TIME_FACTOR * flight.max() + TIME_SLACK))


def agents_list(
    starts: np.ndarray, goals: np.ndarray, r_pz: np.ndarray, speeds: np.ndarray
) -> list[dict[str, Any]]:
    width = len(str(len(starts) - 1))
    return [
        {
            "id": f"u{i:0{width}d}",
            "start": to_mm(starts[i]),
            "goal": to_mm(goals[i]),
            "r_pz": to_mm(r_pz[i]),
            "max_speed": to_mm(speeds[i], SPEED_DECIMALS),
        }
        for i in range(len(starts))
    ]


def base_scenario(
    *,
    v_max: float,
    altitude: tuple[float, float],
    starts: np.ndarray,
    goals: np.ndarray,
    r_pz: np.ndarray,
    speeds: np.ndarray,
) -> dict[str, Any]:
    """The scenario keys every family shares (Table 1 sensing, radius 0.5 m, dt 0.2 s)."""
    return {
        "dt": DT,
        "max_time": max_time_for(starts, goals, speeds),
        "goal_tolerance": 1.0,
        "limits": {
            "speed": [0.0, float(v_max)],
            "altitude": [float(altitude[0]), float(altitude[1])],
        },
        "sensing": {"vehicle_range": 55.0, "obstacle_range": 55.0},
        "defaults": {"r_pz": 10.0, "radius": 0.5, "max_speed": float(v_max)},
        "agents": agents_list(starts, goals, r_pz, speeds),
    }


def place_apart(
    sample: Callable[[], np.ndarray],
    taken: list[np.ndarray],
    min_dist: float,
    *,
    accept: Callable[[np.ndarray], bool] = lambda p: True,
    tries: int = 200,
) -> np.ndarray | None:
    """A point from ``sample()`` at least ``min_dist`` from every point in ``taken`` and
    ``accept``-ed (None after ``tries`` failures: the caller then rejects its whole draw)."""
    for _ in range(tries):
        p = sample()
        if accept(p) and all(np.linalg.norm(p - q) >= min_dist for q in taken):
            return p
    return None


def unit_perpendicular(u: np.ndarray, angle: float) -> np.ndarray:
    """The unit vector at ``angle`` around the axis ``u`` in the plane perpendicular to it."""
    u = u / np.linalg.norm(u)
    helper = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    return math.cos(angle) * e1 + math.sin(angle) * e2
